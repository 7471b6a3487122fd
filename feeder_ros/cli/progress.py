"""A one-line text progress bar on stderr, shared by the ``feeder`` sub-commands."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import TextIO

__all__ = ["ProgressBar"]


class ProgressBar:
    """``ProgressBar(label, total, enabled)``; ``update(done)`` redraws only when the percentage
    changes; ``relabel(label)`` starts a new line for a new item; ``close()`` ends the line.

    After the first second of an item the line also shows the time it has taken, the rate (in
    ``unit`` per second, when a unit is given) and the time left at that rate (``ETA``).

    Disabled bars do nothing, so callers need no conditionals (enable it when stderr is a TTY
    or the user asked for ``--progress``).
    """

    WIDTH = 25

    def __init__(
        self,
        label: str,
        total: float,
        enabled: bool,
        stream: TextIO | None = None,
        unit: str = "",
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.label = label
        self.total = float(total)
        self.enabled = enabled
        self.unit = unit
        self._stream = stream if stream is not None else sys.stderr
        self._clock = clock
        self._started = clock()
        self._last = -1
        self._drawn = False
        self._width = 0  # of the line drawn last (a shorter one pads it out)

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
        line = f"{self.label} [{bar:<{self.WIDTH}}] {percent:3d}%{self._timing(done, fraction)}"
        self._stream.write(f"\r{line:<{self._width}}")
        self._stream.flush()
        self._width = len(line)
        self._drawn = True

    def _timing(self, done: float, fraction: float) -> str:
        elapsed = self._clock() - self._started
        if elapsed < 1.0:
            return ""
        text = f"  {_clock_text(elapsed)}"
        if self.unit:
            text += f", {done / elapsed:.3g} {self.unit}/s"
        if 0.0 < fraction < 1.0:
            text += f", ETA {_clock_text(elapsed * (1.0 - fraction) / fraction)}"
        return text

    def relabel(self, label: str, total: float | None = None) -> None:
        """Finish the current line (if drawn) and go on with another item."""
        if self.enabled and self._drawn:
            self._stream.write("\n")
        self.label = label
        if total is not None:
            self.total = float(total)
        self._last = -1
        self._drawn = False
        self._width = 0
        self._started = self._clock()

    def close(self) -> None:
        if self.enabled and self._drawn:
            self._stream.write("\n")
            self._stream.flush()
        self._drawn = False


def _clock_text(seconds: float) -> str:
    """``m:ss`` (``h:mm:ss`` from an hour)."""
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"
