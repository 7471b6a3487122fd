"""Heartbeat watchdog on a caller-supplied time base: alive while the last beat is recent enough."""

from __future__ import annotations

import math

__all__ = ["Watchdog"]


class Watchdog:
    """``Watchdog(timeout_s)``: ``feed(now)`` on each heartbeat; ``alive(now)``; 0 s disables it.

    Never fed means not alive. A clock that jumps back (sim time restarted) counts the jump as a
    fresh beat rather than as an age below zero that would never expire.
    """

    def __init__(self, timeout_s: float) -> None:
        if not math.isfinite(timeout_s) or timeout_s < 0.0:
            raise ValueError(f"watchdog timeout_s={timeout_s!r} must be a finite value >= 0")
        self.timeout_s = timeout_s
        self._last_s: float | None = None

    @property
    def enabled(self) -> bool:
        return self.timeout_s > 0.0

    def feed(self, now_s: float) -> None:
        self._last_s = now_s

    def age_s(self, now_s: float) -> float:
        """Seconds since the last beat (inf if none)."""
        if self._last_s is None:
            return math.inf
        if now_s < self._last_s:
            self._last_s = now_s
        return now_s - self._last_s

    def alive(self, now_s: float) -> bool:
        return not self.enabled or self.age_s(now_s) <= self.timeout_s
