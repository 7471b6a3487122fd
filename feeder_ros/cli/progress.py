"""A one-line text progress bar on stderr, shared by the ``feeder`` sub-commands."""

from __future__ import annotations

import math
import sys
from typing import TextIO

__all__ = ["ProgressBar"]


class ProgressBar:
    """``ProgressBar(label, total, enabled)``; ``update(done)`` redraws only when the percentage
    changes; ``relabel(label)`` starts a new line for a new item; ``close()`` ends the line.

    Disabled bars do nothing, so callers need no conditionals (enable it when stderr is a TTY
    or the user asked for ``--progress``).
    """

    WIDTH = 25

    def __init__(
        self, label: str, total: float, enabled: bool, stream: TextIO | None = None
    ) -> None:
        self.label = label
        self.total = float(total)
        self.enabled = enabled
        self._stream = stream if stream is not None else sys.stderr
        self._last = -1
        self._drawn = False

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        if not math.isfinite(done):
            return
        fraction = min(max(done / self.total, 0.0), 1.0) if self.total > 0 else 1.0
        percent = int(100.0 * fraction)
        if percent == self._last:
            return
        self._last = percent
        bar = "#" * (percent * self.WIDTH // 100)
        self._stream.write(f"\r{self.label} [{bar:<{self.WIDTH}}] {percent:3d}%")
        self._stream.flush()
        self._drawn = True

    def relabel(self, label: str, total: float | None = None) -> None:
        """Finish the current line (if drawn) and go on with another item."""
        if self.enabled and self._drawn:
            self._stream.write("\n")
        self.label = label
        if total is not None:
            self.total = float(total)
        self._last = -1
        self._drawn = False

    def close(self) -> None:
        if self.enabled and self._drawn:
            self._stream.write("\n")
            self._stream.flush()
        self._drawn = False
