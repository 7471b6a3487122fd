"""A node that judges input silence must not blame an input for its own stall.

A node that judges "no estimate for 2 s" in a timer callback was itself not running while its
process stalled (CPU starvation on a loaded cell computer, memory reclaim, a debugger, SIGSTOP).
The messages sent meanwhile are still on their way: queued in the middleware, or lost packets
that the reliable protocol repairs a moment later. Judged at once, a live input looks silent: a
speed monitor stopped for 2.6 s reported "sensor timeout" (ERROR) on resuming while estimates had
kept coming, and was at target again a second later.

:class:`StallDetector` recognises such a stall by the timer tick that comes late; the node then
counts silence from the end of the middleware's catch-up after it. It never reports two ticks in
a row: for a node starved for good, every other tick judges the inputs as they are (once the
catch-up is over). Plain Python (no rclpy): the nodes feed it a steady clock, the wall clock the
middleware runs on, even when the node clock is a simulation's ``/clock`` running faster than
real time (3 s of catch-up are then 30 s of a 10x simulation).
"""

from __future__ import annotations

import math

#: after a node's own stall, the seconds the middleware gets to deliver what was sent meanwhile
#: before silence counts: a reliable reader that missed samples while stopped gets them again
#: after the writer's next heartbeat (Fast DDS: every 3 s by default). Measured: a speed monitor
#: stopped for 2.6 s heard the estimator again 0.4-2.4 s after it resumed (4 runs).
MIDDLEWARE_CATCH_UP_S = 3.0


class StallDetector:
    """``stalled(now)`` is true for a tick more than ``period_s + slack_s`` after the last one
    (or after ``start_s``, when the timer was created: a node that stalls before its first tick,
    e.g. compiling a kernel at start-up, stalled too), unless the last tick was reported. Without
    ``start_s`` the first tick is never late. A node calls
    :meth:`resuming` at every tick instead: true from a reported stall until ``catch_up_s`` after
    it, while silence must not count."""

    def __init__(
        self,
        period_s: float,
        slack_s: float = 0.5,
        catch_up_s: float = MIDDLEWARE_CATCH_UP_S,
        start_s: float = math.nan,
    ) -> None:
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f"period_s={period_s!r} must be a positive number of seconds")
        if not (math.isfinite(slack_s) and slack_s >= 0.0):
            raise ValueError(f"slack_s={slack_s!r} must be a non-negative number of seconds")
        if not (math.isfinite(catch_up_s) and catch_up_s >= 0.0):
            raise ValueError(f"catch_up_s={catch_up_s!r} must be a non-negative number of seconds")
        self.period_s = period_s
        self.slack_s = slack_s
        self.catch_up_s = catch_up_s
        self._last = float(start_s)
        self._reported = False
        self._catch_up_end = -math.inf
        self.stalls = 0  #: stalls reported so far (for the node's diagnostics)
        self.last_stall_s = 0.0  #: the last reported stall's gap between ticks (s)

    def diagnostic_values(self) -> dict[str, str]:
        """The stalls seen so far and the last one's gap, as a node's diagnostic key values."""
        return {"stalls_seen": str(self.stalls), "last_stall_s": f"{self.last_stall_s:.3f}"}

    def stalled(self, now_s: float) -> bool:
        """Whether the process stalled before the tick at ``now_s`` (a steady clock, seconds)."""
        gap = now_s - self._last
        self._last = now_s
        if gap > self.period_s + self.slack_s and not self._reported:
            self._reported = True
            self.stalls += 1
            self.last_stall_s = gap
            self._catch_up_end = now_s + self.catch_up_s
            return True
        self._reported = False
        return False

    def resuming(self, now_s: float) -> bool:
        """The tick at ``now_s`` (:meth:`stalled`'s clock): whether it lies in a stall's
        catch-up, from the stalled tick on, when the node listens again and silence does not
        count yet."""
        stalled = self.stalled(now_s)
        return stalled or now_s < self._catch_up_end
