"""A feeder's run as the cell saw it, from a bag: the speed monitor's ``speed/status`` (target,
estimate with its uncertainty, transit speed, level) and the drive's ``drive/state`` (state,
frequency, amplitude, fault reason) over time, and what a production engineer asks of them.

ROS free. :class:`RunLog` keeps both streams' columns as the bag is read (a few numbers per
message; the monitor publishes at 2 Hz and the drive at 50 Hz, about 50 MB for a day's bag at
most); :func:`run_figures` reduces them to the headline figures: time driven, time with a target,
time at target (the monitor's own verdict: its status says "at target" only when the estimate's
95 % interval lies within the tolerance), and the faults with their durations; :func:`targets`
gives each drive segment its target speed.

A status counts for the time until the next one, at most :data:`HOLD_LIMIT` periods of the
stream (a recording gap is not counted as time at target).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from feeder_ros.bag.accumulator import stamps
from feeder_ros.bag.reader import ColumnBatch

__all__ = [
    "DRIVE_STATE",
    "REQUESTS",
    "SPEED_STATUS",
    "Fault",
    "RunFigures",
    "RunLog",
    "Series",
    "run_figures",
    "targets",
]

SPEED_STATUS = "feeder_ros/msg/SpeedStatus"
DRIVE_STATE = "feeder_ros/msg/DriveState"
_STAMP = ["header.stamp.sec", "header.stamp.nanosec"]
_SPEED_FIELDS = [
    "target_speed_mps",
    "estimated_speed_mps",
    "estimated_speed_uncertainty_mps",
    "transit_speed_mps",
    "feed_rate_ppm",
    "level",
    "message",
]
_DRIVE_FIELDS = ["state", "frequency_hz", "amplitude_percent", "fault_reason"]
REQUESTS: dict[str, list[str]] = {
    SPEED_STATUS: [*_STAMP, *_SPEED_FIELDS],
    DRIVE_STATE: [*_STAMP, *_DRIVE_FIELDS],
}
#: DriveState.state values (msg/DriveState.msg)
STATE_NAMES = {0: "idle", 1: "ramping", 2: "running", 3: "fault", 4: "e-stop", 5: "paused"}
_DRIVING = (1, 2)  # ramping, running: the output is on
_FAULTS = (3, 4)
#: a sample holds until the next one, at most this many of the stream's median periods
HOLD_LIMIT = 5.0

I64 = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Series:
    """One stream's columns in time order: ``t_ns`` (stamps) and each field's values."""

    t_ns: I64
    columns: dict[str, npt.NDArray[np.generic]]

    def __getitem__(self, name: str) -> npt.NDArray[np.generic]:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.t_ns)

    def held_s(self, end_ns: int) -> npt.NDArray[np.float64]:
        """Seconds each sample holds: to the next sample (the last: to ``end_ns``), at most
        :data:`HOLD_LIMIT` median periods."""
        t = self.t_ns
        if len(t) == 0:
            return np.zeros(0)
        until = np.append(t[1:], max(int(end_ns), int(t[-1])))
        held = (until - t) * 1e-9
        period = float(np.median(held[:-1])) if len(t) > 1 else math.inf
        return np.asarray(np.minimum(held, HOLD_LIMIT * period), dtype=np.float64)


class RunLog:
    """The speed status and drive state columns of one feeder, batch by batch."""

    def __init__(self) -> None:
        self._batches: dict[str, list[tuple[I64, dict[str, npt.NDArray[np.generic]]]]] = {
            SPEED_STATUS: [],
            DRIVE_STATE: [],
        }
        self._series: dict[str, Series | None] = {}

    def add(self, batch: ColumnBatch) -> None:
        if batch.type not in self._batches or len(batch) == 0:
            return
        self._series.pop(batch.type, None)
        fields = _SPEED_FIELDS if batch.type == SPEED_STATUS else _DRIVE_FIELDS
        self._batches[batch.type].append(
            (stamps(batch), {name: np.asarray(batch[name]) for name in fields})
        )

    def series(self, kind: str) -> Series | None:
        """The stream of ``kind`` (SPEED_STATUS or DRIVE_STATE) in time order; None if absent.
        Built once, after the last :meth:`add` (the figures, targets and plots all read it)."""
        if kind not in self._series:
            self._series[kind] = self._build(kind)
        return self._series[kind]

    def _build(self, kind: str) -> Series | None:
        parts = self._batches[kind]
        if not parts:
            return None
        t = np.concatenate([p[0] for p in parts])
        order = np.argsort(t, kind="stable")
        columns = {name: np.concatenate([p[1][name] for p in parts])[order] for name in parts[0][1]}
        return Series(t[order], columns)


@dataclass(frozen=True)
class Fault:
    """The drive in FAULT or E-STOP from ``start_s`` to ``end_s`` (seconds from the run's start;
    ``end_s`` NaN: still in it when the bag ends)."""

    start_s: float
    end_s: float
    state: str
    reason: str

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True)
class RunFigures:
    """Headline figures of a run (seconds; NaN where the bag lacks the stream)."""

    run_s: float
    driving_s: float  # drive output on (ramping or running), from drive/state
    target_s: float  # a target speed set while driving, from speed/status
    at_target_s: float  # of that, the monitor said "at target"
    parts_fed: int
    feed_rate_per_min: float  # parts fed over the run time
    faults: tuple[Fault, ...]

    @property
    def at_target_share(self) -> float:
        return self.at_target_s / self.target_s if self.target_s > 0 else math.nan


def faults(drive: Series | None, start_ns: int) -> list[Fault]:
    """The stretches the drive spent in FAULT or E-STOP, with the reason it gave first."""
    if drive is None:
        return []
    state = drive["state"].astype(np.int64)
    found: list[Fault] = []
    k, n = 0, len(drive)
    while k < n:
        if int(state[k]) not in _FAULTS:
            k += 1
            continue
        first = k
        while k < n and int(state[k]) == int(state[first]):
            k += 1
        end = (int(drive.t_ns[k]) - start_ns) * 1e-9 if k < n else math.nan
        found.append(
            Fault(
                (int(drive.t_ns[first]) - start_ns) * 1e-9,
                end,
                STATE_NAMES[int(state[first])],
                str(drive["fault_reason"][first]),
            )
        )
    return found


def _driving_at(drive: Series | None, t_ns: I64) -> npt.NDArray[np.bool_]:
    """Whether the drive's output was on at each time (all true without drive/state)."""
    if drive is None:
        return np.ones(len(t_ns), dtype=bool)
    k = np.searchsorted(drive.t_ns, t_ns, side="right") - 1
    state = drive["state"].astype(np.int64)
    return (k >= 0) & np.isin(state[np.maximum(k, 0)], _DRIVING)


def run_figures(log: RunLog, start_ns: int, end_ns: int, parts_fed: int) -> RunFigures:
    """The headline figures of a run from ``start_ns`` to ``end_ns``."""
    run_s = (end_ns - start_ns) * 1e-9
    drive = log.series(DRIVE_STATE)
    speed = log.series(SPEED_STATUS)
    driving_s = math.nan
    if drive is not None:
        on = np.isin(drive["state"].astype(np.int64), _DRIVING)
        driving_s = float(drive.held_s(end_ns)[on].sum())
    target_s = at_target_s = math.nan
    if speed is not None:
        held = speed.held_s(end_ns)
        with_target = np.isfinite(speed["target_speed_mps"].astype(np.float64))
        with_target &= _driving_at(drive, speed.t_ns)
        at_target = with_target & (speed["level"].astype(np.int64) == 0)
        at_target &= np.char.startswith(speed["message"].astype(str), "at target")
        target_s = float(held[with_target].sum())
        at_target_s = float(held[at_target].sum())
    return RunFigures(
        run_s=run_s,
        driving_s=driving_s,
        target_s=target_s,
        at_target_s=at_target_s,
        parts_fed=parts_fed,
        feed_rate_per_min=parts_fed / (run_s / 60.0) if run_s > 0 else math.nan,
        faults=tuple(faults(drive, start_ns)),
    )


def targets(log: RunLog, spans: Sequence[tuple[float, float]], start_ns: int) -> list[float]:
    """Per span (start, end: seconds from the run's start; a drive segment), the target speed
    the monitor held during it (the median of its statuses with a target, m/s); NaN where none
    was set or the bag has no speed status."""
    speed = log.series(SPEED_STATUS)
    if speed is None:
        return [math.nan] * len(spans)
    t = (speed.t_ns - start_ns) * 1e-9
    target = speed["target_speed_mps"].astype(np.float64)
    found = []
    for lo, hi in spans:
        inside = (t >= lo) & (t < hi) & np.isfinite(target)
        found.append(float(np.median(target[inside])) if inside.any() else math.nan)
    return found
