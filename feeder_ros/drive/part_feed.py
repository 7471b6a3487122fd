"""The ``feed_parts`` action's decisions, ROS-free: count parts past a part-present sensor, or wait
for one at the pick position, and say when and how the goal ends.

:class:`PartFeed` is driven by the node with explicit times (the node clock, in seconds): it is
told the sensor edges (``edge``), whether the drive is feeding (``update``), a cancel or an end
the node saw (``cancel``, ``abort``), and answers with a :class:`FeedProgress`; once done, that
progress is frozen. The node follows this policy (``action/FeedParts.action`` says the same):

- **One goal at a time, no queue.** The action server accepts every goal so that a refused one can
  say why: it ends at once with ``OUTCOME_REFUSED`` (6, the node's, not a :class:`FeedOutcome`)
  and the reason, and nothing changes. Refused are a second goal while one runs (that one goes
  on), a goal :func:`request_refusal` objects to, and a drive that cannot start (fault latched,
  not active, no heartbeat). A goal's ``starvation_timeout_s`` of 0 means the node's default
  (``feed.starvation_timeout_s``), substituted before :func:`request_refusal` sees it.
- **The drive** is started at its stored set point (``set_drive``/``set_target_speed`` first)
  when the goal is accepted, and ramped to zero when the goal ends, whatever the reason; the
  result is sent once the output is off. An UNTIL_PRESENT goal whose sensor is already covered
  succeeds at once with 0 parts and never starts the drive.
- **Ends from the node:** a cancel -> CANCELED; an emergency stop -> ESTOPPED; a drive fault ->
  FAULTED (the heartbeat watchdog still applies: a lost heartbeat faults the drive); the drive
  deactivated, stopped by another client or the node shutting down -> ABORTED, with the reason.
- **Feeding** (``update``'s flag) means the drive is outputting vibration: enabled, started and
  not paused by track level control. Starvation counts feeding time only: the time between two
  updates counts when both say feeding, so a ramp-up or a level-control pause does not count
  (the time-out is reached at most one update late, never early).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

__all__ = [
    "MAX_PARTS_PER_GOAL",
    "PART_ID_UNKNOWN",
    "FeedMode",
    "FeedOutcome",
    "FeedProgress",
    "FeedRequest",
    "PartFeed",
    "request_refusal",
]

PART_ID_UNKNOWN = 4294967295  # PartSensorEvent.PART_ID_UNKNOWN: a real sensor does not know
MAX_PARTS_PER_GOAL = 10000  # larger counts are refused as absurd


class FeedMode(IntEnum):
    """Same values as FeedParts.Goal's MODE_* constants."""

    COUNT = 0  # part_count parts past the sensor, each counted on its falling edge
    UNTIL_PRESENT = 1  # a part at the sensor (the pick position): its rising edge


class FeedOutcome(IntEnum):
    """Same values as FeedParts.Result's OUTCOME_* constants."""

    SUCCEEDED = 0
    STARVED = 1  # no part delivered for starvation_timeout_s of feeding
    FAULTED = 2  # the drive faulted
    ESTOPPED = 3  # emergency stop
    CANCELED = 4  # the client canceled
    ABORTED = 5  # anything else (deactivated, stopped by another client, shutting down)


_NODE_ENDS = (FeedOutcome.FAULTED, FeedOutcome.ESTOPPED, FeedOutcome.ABORTED)


def _seconds(value: float) -> str:
    return f"{value:.1f}" if value >= 1.0 else f"{value:.3g}"


def _parts(n: int) -> str:
    return f"{n} part" if n == 1 else f"{n} parts"


def _finite(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise ValueError(f"{name}={value!r} must be finite")
    return value


def _goal_refusal(mode: int, part_count: int, starvation_timeout_s: float) -> str:
    """The checks that need no knowledge of the feeder (all but the sensor's range)."""
    if isinstance(mode, bool) or mode not in (FeedMode.COUNT, FeedMode.UNTIL_PRESENT):
        return f"mode={mode!r}: expected 0 (COUNT) or 1 (UNTIL_PRESENT)"
    whole = isinstance(part_count, int) and not isinstance(part_count, bool)
    if mode == FeedMode.COUNT and not (whole and 1 <= part_count <= MAX_PARTS_PER_GOAL):
        kind = "" if whole else " (an integer)"
        return f"part_count={part_count!r}: a COUNT goal needs 1..{MAX_PARTS_PER_GOAL} parts{kind}"
    if mode == FeedMode.UNTIL_PRESENT and not (whole and part_count == 0):
        return f"part_count={part_count!r}: an UNTIL_PRESENT goal takes no count (0)"
    if not (math.isfinite(starvation_timeout_s) and starvation_timeout_s > 0.0):
        return f"starvation_timeout_s={starvation_timeout_s!r} must be finite and > 0"
    return ""


def request_refusal(
    mode: int, part_count: int, sensor_index: int, starvation_timeout_s: float, sensor_count: int
) -> str:
    """'' when the goal is acceptable, else the reason, naming the offending value."""
    refusal = _goal_refusal(mode, part_count, starvation_timeout_s)
    if refusal or 0 <= sensor_index < sensor_count:
        return refusal
    if sensor_count <= 0:
        return f"sensor_index={sensor_index}: the feeder has no part-present sensors"
    sensors = "sensor" if sensor_count == 1 else "sensors"
    return (
        f"sensor_index={sensor_index}: the feeder has {sensor_count} part-present {sensors} "
        f"(0..{sensor_count - 1})"
    )


@dataclass(frozen=True)
class FeedRequest:
    """A goal that passed :func:`request_refusal`; a bad one raises ValueError with the reason."""

    mode: FeedMode
    part_count: int  # COUNT: 1..MAX_PARTS_PER_GOAL; UNTIL_PRESENT: 0
    sensor_index: int
    starvation_timeout_s: float  # > 0, finite

    def __post_init__(self) -> None:
        refusal = _goal_refusal(self.mode, self.part_count, self.starvation_timeout_s)
        if not refusal and self.sensor_index < 0:
            refusal = f"sensor_index={self.sensor_index} must be >= 0"
        if refusal:
            raise ValueError(refusal)
        object.__setattr__(self, "mode", FeedMode(self.mode))


@dataclass(frozen=True)
class FeedProgress:
    delivered: int
    elapsed_s: float  # goal start to now, or to the end when done
    done: bool
    outcome: FeedOutcome | None  # set when done
    reason: str  # the result's text when done, a status line before
    time_per_part_s: float  # elapsed_s / delivered; NaN when none delivered
    last_delivery_s: float  # time of the last delivery; NaN when none


class PartFeed:
    """``PartFeed(request, t_start_s, sensor_covered)``: one goal, from its acceptance at
    ``t_start_s``; ``sensor_covered`` is the goal sensor's last known state (None: unknown)."""

    def __init__(
        self, request: FeedRequest, t_start_s: float, sensor_covered: bool | None = None
    ) -> None:
        self.request = request
        self.t_start_s = _finite("t_start_s", t_start_s)
        self._delivered = 0
        self._seen: set[int] = set()  # known part ids already counted
        self._last_delivery_s = math.nan
        self._fed_s = 0.0  # feeding time since the later of goal start / last delivery
        self._since_s = t_start_s  # ... counted from here
        self._last_t_s = t_start_s
        self._last_feeding = False
        self._final: FeedProgress | None = None
        if request.mode is FeedMode.UNTIL_PRESENT and sensor_covered:
            where = f"sensor {request.sensor_index}"
            self._end(t_start_s, FeedOutcome.SUCCEEDED, f"a part was already at {where}")

    @property
    def done(self) -> bool:
        return self._final is not None

    def edge(self, t_s: float, sensor_index: int, part_id: int, present: bool) -> None:
        """A part-present edge (``present``: a part arrived; else it has passed the sensor)."""
        _finite("t_s", t_s)
        request = self.request
        if self._final is not None or sensor_index != request.sensor_index or t_s < self.t_start_s:
            return
        until_present = request.mode is FeedMode.UNTIL_PRESENT
        if bool(present) != until_present:
            return  # COUNT counts falling edges (a part has passed), UNTIL_PRESENT a rising one
        if part_id != PART_ID_UNKNOWN and not until_present:
            if part_id in self._seen:
                return  # the same part's edge again (a repeated message)
            self._seen.add(part_id)
        self._deliver(t_s)
        elapsed = _seconds(t_s - self.t_start_s)
        if until_present:
            reason = f"a part reached sensor {sensor_index} in {elapsed} s"
            self._end(t_s, FeedOutcome.SUCCEEDED, reason)
        elif self._delivered >= request.part_count:
            reason = f"delivered {_parts(self._delivered)} in {elapsed} s"
            self._end(t_s, FeedOutcome.SUCCEEDED, reason)

    def update(self, t_s: float, feeding: bool) -> FeedProgress:
        """The progress at ``t_s``; ``feeding``: the drive outputs vibration now."""
        _finite("t_s", t_s)
        if self._final is not None:
            return self._final
        counted_from = max(self._last_t_s, self._since_s)
        if feeding and self._last_feeding and t_s > counted_from:
            self._fed_s += t_s - counted_from
        self._last_t_s, self._last_feeding = t_s, feeding  # a clock jumping back counts nothing
        request = self.request
        if self._fed_s >= request.starvation_timeout_s:
            timeout, sensor = _seconds(request.starvation_timeout_s), request.sensor_index
            if request.mode is FeedMode.COUNT:
                of = f"{self._delivered} of {request.part_count} delivered"
                reason = f"starved: no part past sensor {sensor} for {timeout} s of feeding ({of})"
            else:
                reason = f"starved: no part reached sensor {sensor} in {timeout} s of feeding"
            return self._end(t_s, FeedOutcome.STARVED, reason)
        return self._progress(t_s, None, self._so_far())

    def cancel(self, t_s: float) -> FeedProgress:
        """The client canceled: CANCELED, unless the goal has already ended."""
        _finite("t_s", t_s)
        if self._final is not None:
            return self._final
        return self._end(t_s, FeedOutcome.CANCELED, f"canceled by the client ({self._so_far()})")

    def abort(self, t_s: float, outcome: FeedOutcome, reason: str) -> FeedProgress:
        """The node ended the goal (FAULTED, ESTOPPED or ABORTED), unless it has already ended."""
        _finite("t_s", t_s)
        if outcome not in _NODE_ENDS:
            raise ValueError(f"outcome={outcome!r}: abort takes FAULTED, ESTOPPED or ABORTED")
        if self._final is not None:
            return self._final
        return self._end(t_s, outcome, reason or FeedOutcome(outcome).name.lower())

    # -- internals ---------------------------------------------------------------------------------
    def _so_far(self) -> str:
        if self.request.mode is FeedMode.COUNT:
            return f"{self._delivered} of {self.request.part_count} parts delivered"
        return f"waiting for a part at sensor {self.request.sensor_index}"

    def _deliver(self, t_s: float) -> None:
        self._delivered += 1
        self._fed_s = 0.0
        self._since_s = max(self._since_s, t_s)  # edges may come out of order
        self._last_delivery_s = self._since_s  # (edges before the start are ignored)

    def _progress(self, t_s: float, outcome: FeedOutcome | None, reason: str) -> FeedProgress:
        elapsed = max(0.0, t_s - self.t_start_s)
        n = self._delivered
        return FeedProgress(
            delivered=n,
            elapsed_s=elapsed,
            done=outcome is not None,
            outcome=outcome,
            reason=reason,
            time_per_part_s=elapsed / n if n else math.nan,
            last_delivery_s=self._last_delivery_s,
        )

    def _end(self, t_s: float, outcome: FeedOutcome, reason: str) -> FeedProgress:
        self._final = self._progress(t_s, outcome, reason)
        return self._final
