"""The ``feeder`` sub-commands' progress bar on stderr, drawn by ``tqdm``.

:class:`ProgressBar` keeps the commands' calls simple (the work reports how far it is, not by how
much it moved) and the line's content fixed: label, percentage, bar, then done/total in ``unit``,
the elapsed time, the time left at the rate so far and the rate (a bar without a unit, over a
fraction such as a file read, shows the times only). ``tqdm`` redraws at most ten times a second
and fits the line to the terminal.
"""

from __future__ import annotations

import math
import sys
from typing import Any, TextIO

from tqdm import tqdm

__all__ = ["ProgressBar"]

_WITH_UNIT = (
    "{desc} {percentage:3.0f}%|{bar}| {n:,.6g}/{total:,.6g}{unit} "
    "[{elapsed}<{remaining}, {rate_noinv_fmt}]"
)
_FRACTION = "{desc} {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]"


class ProgressBar:
    """``ProgressBar(label, total, enabled)``; ``update(done)`` moves it to ``done`` of ``total``
    (a NaN is ignored, values are clipped to ``0..total``); ``relabel(label)`` ends the line and
    starts one for the next item; ``close()`` ends the line.

    A disabled bar writes nothing, so callers need no conditionals (enable it when stderr is a
    TTY or the user asked for ``--progress``).
    """

    def __init__(
        self,
        label: str,
        total: float,
        enabled: bool,
        stream: TextIO | None = None,
        unit: str = "",
    ) -> None:
        self.label = label
        self.total = float(total)
        self.enabled = enabled
        self.unit = unit
        self._stream = stream
        self._bar: Any = None
        self._open()

    def _open(self) -> None:
        self._bar = tqdm(
            total=self.total,
            desc=self.label,
            unit=f" {self.unit}" if self.unit else "it",  # " sim s": "1.3 sim s/s"
            disable=not self.enabled,
            file=self._stream if self._stream is not None else sys.stderr,
            bar_format=_WITH_UNIT if self.unit else _FRACTION,
            dynamic_ncols=True,
            leave=True,
        )

    def update(self, done: float) -> None:
        if not self.enabled or not math.isfinite(done):
            return
        done = min(max(float(done), 0.0), self.total)
        if done != self._bar.n:
            self._bar.update(done - self._bar.n)

    def relabel(self, label: str, total: float | None = None) -> None:
        """Finish the current line and go on with another item."""
        self._bar.close()
        self.label = label
        if total is not None:
            self.total = float(total)
        self._open()

    def close(self) -> None:
        self._bar.close()
