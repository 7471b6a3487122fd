"""The physics core's run-time failure, importable without the solver (``feeder`` catches it)."""

from __future__ import annotations

__all__ = ["SimulationError"]


class SimulationError(RuntimeError):
    """The solver could not continue; the message says why and where."""
