"""The design search's objectives by name (a module of its own: the ``feeder design`` command's
options need them without loading the optimizer and the physics core)."""

from __future__ import annotations

from typing import Final

__all__ = ["OBJECTIVES"]

#: max-speed: the fastest parts; min-force: a target speed with the least drive amplitude
OBJECTIVES: Final[tuple[str, ...]] = ("max-speed", "min-force")
