"""Streaming analysis of feeder bags: drive segments, part speed, slip, feed rate, diagnostics.

ROS free: reads bags with :func:`~feeder_ros.bag.read_tables` (one pass, column batches chunk by
chunk) and, when the bag holds ``diagnostic_msgs/DiagnosticArray``, a second pass over those
messages only. Topics are recognised by TYPE, so namespaced or remapped feeder topics are found and
unrelated topics are ignored. One feeder per bag: several topics of one feeder type are analysed
together (and reported as a problem).

Time axis: every message's ``header.stamp`` (the feeder's own clock; the log time where a stamp is
zero). Segments of constant drive setting (frequency, amplitude; "off" when the amplitude is zero or
the drive disabled) come from ``CarrierState``/``CarrierStateBatch`` (the drive actually applied)
or, in bags without carrier state, from ``DriveCommand``. A segment runs from the first sample with
its setting to the first sample with the next one.

Per segment: mean part speed from the estimator (``VehicleEstimate.mean_speed_mps``, samples with
status OK), from ground truth (``PartStateArray``: mean velocity of the parts on the track) and
from part-present sensor transits (``PartSensorEvent`` rising edges of one part at two sensors:
distance over time, counted in the segment of the second edge); slip fraction from the estimator
and from the ground-truth phases; feed rate from ``PartExit``. Segments shorter than
``min_segment_s`` (ramps) are counted as transient and left out. ``DiagnosticArray`` is decoded
message by message (its ``KeyValue[]`` inside ``status[]`` does not fit the column decoder).

Memory is bounded: metric samples wait in a small pending buffer until the drive timeline has
passed their time, then are reduced into per-segment sums (``np.bincount``); only change points,
per-segment sums and diagnostic level changes are kept.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from feeder_ros.bag.errors import BagError, BagProblem, UnsupportedLayoutError
from feeder_ros.bag.reader import LOG_TIME, Bag, ColumnBatch, bag_info, iter_messages, read_tables

__all__ = [
    "FEEDER_TYPES",
    "AnalysisError",
    "BagAnalysis",
    "DiagnosticChange",
    "FrequencyPoint",
    "Segment",
    "analyze_bag",
    "analyze_bags",
]

DRIVE_COMMAND = "feeder_ros/msg/DriveCommand"
CARRIER_STATE = "feeder_ros/msg/CarrierState"
CARRIER_STATE_BATCH = "feeder_ros/msg/CarrierStateBatch"
VEHICLE_ESTIMATE = "feeder_ros/msg/VehicleEstimate"
PART_STATE_ARRAY = "feeder_ros/msg/PartStateArray"
PART_SENSOR_EVENT = "feeder_ros/msg/PartSensorEvent"
PART_EXIT = "feeder_ros/msg/PartExit"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
#: the longest CarrierStateBatch sample period taken (the vehicle estimator node's limit) [s]
MAX_SAMPLE_PERIOD_S = 1.0

_STAMP = ["header.stamp.sec", "header.stamp.nanosec"]
REQUESTS: dict[str, list[str]] = {
    DRIVE_COMMAND: [*_STAMP, "enabled", "frequency_hz", "amplitude_n"],
    CARRIER_STATE: [*_STAMP, "drive_frequency_hz", "drive_amplitude_n"],
    CARRIER_STATE_BATCH: [*_STAMP, "sample_period_s", "drive_frequency_hz", "drive_amplitude_n"],
    VEHICLE_ESTIMATE: [*_STAMP, "mean_speed_mps", "slip_fraction", "status"],
    PART_STATE_ARRAY: [*_STAMP, "parts.velocity_mps", "parts.phase", "parts.on_track"],
    PART_SENSOR_EVENT: [*_STAMP, "sensor_index", "sensor_position_m", "part_id", "present"],
    PART_EXIT: [*_STAMP, "part_id"],
}
FEEDER_TYPES = frozenset([*REQUESTS, DIAGNOSTIC_ARRAY])

# per-segment sums and counts of: estimator mean speed and slip (status OK only), ground-truth
# velocity and slip flag per part on the track, sensor transit speeds, exits (value 1 each)
METRICS = ("est_speed", "est_slip", "gt_speed", "gt_slip", "sensor_speed", "exits")
_DIAG_LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
_MAX_DIAG_CHANGES = 10_000
_PENDING_LIMIT = 2_000_000  # metric samples held before a forced flush
_FLUSH_BATCH = 100_000  # metric samples gathered before they are reduced (between chunks)
_COMMAND_MARGIN_NS = 2_000_000_000  # command-only bags: commands may be stamped this much late

Progress = Callable[[float], None]
Setting = tuple[float, float]  # (frequency_hz, amplitude_n); (0, 0) is "off"
OFF: Setting = (0.0, 0.0)


class AnalysisError(BagError):
    """Nothing of a bag could be analysed (no feeder data, unreadable, ...)."""

    def __init__(self, path: Path | str, reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


@dataclass
class Segment:
    """A stretch of constant drive setting and what the feeder did during it (SI units; NaN where
    the bag has no source for a value). ``frequency_hz``/``amplitude_n`` are None before the first
    drive information; ``transient``: shorter than the minimum segment length (ramps)."""

    index: int
    start_s: float
    end_s: float
    frequency_hz: float | None
    amplitude_n: float | None
    speed_estimate_mps: float = math.nan
    slip_estimate: float = math.nan
    speed_ground_truth_mps: float = math.nan
    slip_ground_truth: float = math.nan
    speed_sensors_mps: float = math.nan
    transits: int = 0
    parts_exited: int = 0
    feed_rate_per_min: float = math.nan
    transient: bool = False

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    @property
    def enabled(self) -> bool:
        return self.amplitude_n is not None and self.amplitude_n != 0.0

    @property
    def speed_mps(self) -> float:
        """Best available mean part speed: ground truth, else sensor transits, else estimator."""
        for value in (self.speed_ground_truth_mps, self.speed_sensors_mps, self.speed_estimate_mps):
            if not math.isnan(value):
                return value
        return math.nan

    @property
    def slip_fraction(self) -> float:
        return (
            self.slip_ground_truth if not math.isnan(self.slip_ground_truth) else self.slip_estimate
        )

    def as_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data.update(duration_s=self.duration_s, speed_mps=self.speed_mps)
        data["slip_fraction"] = self.slip_fraction
        return data


@dataclass(frozen=True)
class DiagnosticChange:
    """A diagnostic status whose level changed (first appearance included)."""

    t_s: float
    name: str
    level: int
    message: str

    @property
    def level_name(self) -> str:
        return _DIAG_LEVELS.get(self.level, str(self.level))


@dataclass(frozen=True)
class FrequencyPoint:
    """One operating point of a sweep: duration-weighted means over its segments."""

    amplitude_n: float
    frequency_hz: float
    duration_s: float
    speed_mps: float
    slip_fraction: float
    feed_rate_per_min: float


@dataclass
class BagAnalysis:
    path: Path
    start_ns: int | None = None
    end_ns: int | None = None
    segments: list[Segment] = field(default_factory=list)
    transient_segments: int = 0
    diagnostics: list[DiagnosticChange] = field(default_factory=list)
    frequency_response: list[FrequencyPoint] = field(default_factory=list)
    messages: dict[str, int] = field(default_factory=dict)  # per feeder type
    topics: dict[str, list[str]] = field(default_factory=dict)  # type -> topics
    drive_source: str = "none"
    problems: list[str] = field(default_factory=list)
    cut_short: bool = False
    #: the reader's problems that mean recorded messages could not be read (``Bag.lost_data``:
    #: corrupt chunks and records, missing, unreadable or non-MCAP files, an earlier split file cut
    #: short, malformed messages): counts, exits and feed rates come out short
    data_losses: list[BagProblem] = field(default_factory=list)
    #: of those, the chunks skipped; ``lost_s`` is the recording time the losses spanned as far as
    #: the files tell (chunk headers, metadata.yaml for a missing file): a lower bound
    chunks_lost: int = 0
    lost_s: float = 0.0
    error: str | None = None

    @property
    def name(self) -> str:
        return self.path.name or str(self.path)

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) * 1e-9

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def data_lost(self) -> bool:
        """Recorded messages could not be read (``data_losses``)."""
        return bool(self.data_losses)

    def loss_summary(self) -> str:
        """What was lost, in a few words: "2 corrupt chunk(s) skipped, 1 missing file(s), about
        0.5 s of recording" (the time when the files tell it)."""
        counts: dict[str, int] = {}
        for problem in self.data_losses:
            counts[problem.kind] = counts.get(problem.kind, 0) + 1
        words = [
            f"{n} {_LOSS_WORDS.get(kind, kind.replace('_', ' ') + ' problem(s)')}"
            for kind, n in counts.items()
        ]
        if self.lost_s > 0:
            words.append(f"about {self.lost_s:.3g} s of recording")
        return ", ".join(words)

    def totals(self) -> dict[str, float]:
        """Duration-weighted means over the driven segments, and the overall feed rate."""
        driven = [s for s in self.segments if s.enabled and not s.transient]

        def mean(values: Iterable[tuple[float, float]]) -> float:
            pairs = [(v, w) for v, w in values if not math.isnan(v) and w > 0]
            weight = sum(w for _, w in pairs)
            return sum(v * w for v, w in pairs) / weight if weight > 0 else math.nan

        exited = sum(s.parts_exited for s in self.segments)
        return {
            "duration_s": self.duration_s,
            "driven_s": sum(s.duration_s for s in driven),
            "speed_mps": mean((s.speed_mps, s.duration_s) for s in driven),
            "slip_fraction": mean((s.slip_fraction, s.duration_s) for s in driven),
            "parts_exited": float(exited),
            "feed_rate_per_min": exited / (self.duration_s / 60.0)
            if self.duration_s > 0
            else math.nan,
        }

    def as_dict(self) -> dict[str, Any]:
        return {
            "bag": str(self.path),
            "error": self.error,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "duration_s": self.duration_s,
            "cut_short": self.cut_short,
            "data_losses": [str(p) for p in self.data_losses],
            "chunks_lost": self.chunks_lost,
            "lost_s": self.lost_s,
            "drive_source": self.drive_source,
            "messages": dict(self.messages),
            "topics": {k: list(v) for k, v in self.topics.items()},
            "totals": self.totals(),
            "transient_segments": self.transient_segments,
            "segments": [s.as_dict() for s in self.segments],
            "frequency_response": [asdict(p) for p in self.frequency_response],
            "diagnostics": [{**asdict(d), "level_name": d.level_name} for d in self.diagnostics],
            "problems": list(self.problems),
        }


# ------------------------------------------------------------------------------- accumulation


def _stamps(batch: ColumnBatch) -> npt.NDArray[np.int64]:
    t = batch["header.stamp.sec"].astype(np.int64) * 1_000_000_000 + batch[
        "header.stamp.nanosec"
    ].astype(np.int64)
    log = batch[LOG_TIME].astype(np.int64)
    return np.where(t == 0, log, t)


class _Timeline:
    """Change points of the drive setting, appended in time order."""

    def __init__(self) -> None:
        self.times: list[int] = []
        self.settings: list[Setting] = []
        self.last_t: int | None = None
        #: samples left out because they are stamped before what the timeline already holds
        self.dropped = 0
        self.dropped_last_t = 0  # the timeline's end when the last of them was dropped

    def add(
        self,
        t: npt.NDArray[np.int64],
        freq: npt.NDArray[np.float64],
        amp: npt.NDArray[np.float64],
    ) -> None:
        if len(t) == 0:
            return
        order = np.argsort(t, kind="stable")
        t, freq, amp = t[order], freq[order], amp[order]
        if self.last_t is not None:  # drop samples older than what the timeline already holds
            keep = t >= self.last_t
            if not keep.all():
                self.dropped += int(np.count_nonzero(~keep))
                self.dropped_last_t = self.last_t
            t, freq, amp = t[keep], freq[keep], amp[keep]
            if len(t) == 0:
                return
        off = ~(amp != 0.0) | ~np.isfinite(amp) | ~np.isfinite(freq)
        freq = np.where(off, 0.0, np.round(freq, 9))
        amp = np.where(off, 0.0, np.round(amp, 9))
        changed = np.empty(len(t), dtype=bool)
        changed[1:] = (freq[1:] != freq[:-1]) | (amp[1:] != amp[:-1])
        if self.settings:
            changed[0] = (float(freq[0]), float(amp[0])) != self.settings[-1]
        else:
            changed[0] = True
        for k in np.flatnonzero(changed):
            self.times.append(int(t[k]))
            self.settings.append((float(freq[k]), float(amp[k])))
        self.last_t = int(t[-1])


class _Accumulator:
    """Per-segment sums of metric samples; samples wait until the drive timeline passed them."""

    def __init__(self) -> None:
        self.state = _Timeline()
        self.command = _Timeline()
        self.pending: dict[str, list[tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]]] = {
            m: [] for m in METRICS
        }
        self.pending_count = 0
        self.sums: dict[str, npt.NDArray[np.float64]] = {m: np.zeros(0) for m in METRICS}
        self.counts: dict[str, npt.NDArray[np.float64]] = {m: np.zeros(0) for m in METRICS}
        self.t_min: int | None = None
        self.t_max: int | None = None
        self.last_edge: dict[int, tuple[int, float, int]] = {}  # part -> (sensor, position, t)
        #: values left out, by reason: (count, an example) for the problems list
        self.left_out: dict[str, tuple[int, str]] = {}

    def leave_out(self, reason: str, count: int, example: str) -> None:
        if count:
            seen, first = self.left_out.get(reason, (0, example))
            self.left_out[reason] = (seen + count, first)

    def notes(self, start: int | None) -> list[str]:
        """The problems found in the values: what was left out and why."""
        out = [
            f"[bad_value] {count} {reason} (for example {example})"
            for reason, (count, example) in self.left_out.items()
        ]
        for name, line in (("carrier state", self.state), ("drive command", self.command)):
            if line.dropped:
                at = (line.dropped_last_t - start) * 1e-9 if start is not None else math.nan
                out.append(
                    f"[out_of_order] {line.dropped} {name} sample(s) stamped before the ones "
                    f"already read (up to t = {at:.6g} s) left out: header stamps out of "
                    "order; one far ahead (or sim time mixed with wall time) hides the drive "
                    "changes after it"
                )
        return out

    @property
    def timeline(self) -> _Timeline:
        return self.state if self.state.times else self.command

    def see(self, t: npt.NDArray[np.int64]) -> None:
        if len(t):
            lo, hi = int(t.min()), int(t.max())
            self.t_min = lo if self.t_min is None else min(self.t_min, lo)
            self.t_max = hi if self.t_max is None else max(self.t_max, hi)

    def add(self, metric: str, t: npt.NDArray[np.int64], v: npt.NDArray[Any]) -> None:
        if len(t):
            self.pending[metric].append((t, np.asarray(v, dtype=np.float64)))
            self.pending_count += len(t)

    def flush(self, final: bool = False) -> None:
        """Reduce the pending samples the drive timeline has passed (called between chunks: every
        drive sample of the chunks read so far is in the timeline); all of them when ``final``."""
        if final or self.pending_count > _PENDING_LIMIT:
            cutoff = None
        elif self.state.last_t is not None:
            cutoff = self.state.last_t
        elif self.t_max is not None:
            cutoff = self.t_max - _COMMAND_MARGIN_NS
        else:
            return
        times = np.asarray(self.timeline.times, dtype=np.int64)
        n = len(times) + 1  # segment 0: before the first drive information
        self.pending_count = 0
        for metric, parts in self.pending.items():
            if not parts:
                continue
            t = np.concatenate([p[0] for p in parts])
            v = np.concatenate([p[1] for p in parts])
            if cutoff is not None:
                now = t <= cutoff
                later = ~now
                self.pending[metric] = [(t[later], v[later])] if later.any() else []
                self.pending_count += int(later.sum())
                t, v = t[now], v[now]
            else:
                self.pending[metric] = []
            if len(t) == 0:
                continue
            seg = np.searchsorted(times, t, side="right")
            for target, weights in ((self.sums, v), (self.counts, None)):
                add = np.bincount(seg, weights=weights, minlength=n)
                old = target[metric]
                if len(old) < n:
                    old = np.concatenate([old, np.zeros(n - len(old))])
                old[: len(add)] += add
                target[metric] = old

    # -- per type -------------------------------------------------------------------------------

    def batch(self, batch: ColumnBatch) -> None:
        t = _stamps(batch)
        self.see(t)
        kind = batch.type
        if kind == CARRIER_STATE:
            self._count_drive(batch["drive_frequency_hz"], batch["drive_amplitude_n"])
            self.state.add(t, batch["drive_frequency_hz"], batch["drive_amplitude_n"])
        elif kind == CARRIER_STATE_BATCH:
            self._state_batch(t, batch)
        elif kind == DRIVE_COMMAND:
            amp = np.where(batch["enabled"].astype(bool), batch["amplitude_n"], 0.0)
            self._count_drive(batch["frequency_hz"], amp)
            self.command.add(t, batch["frequency_hz"], amp)
        elif kind == VEHICLE_ESTIMATE:
            ok = batch["status"] == 0
            for metric, name in (("est_speed", "mean_speed_mps"), ("est_slip", "slip_fraction")):
                values = batch[name]
                good = ok & np.isfinite(values)
                self._count_bad(f"non-finite VehicleEstimate.{name} left out", ok & ~good, values)
                self.add(metric, t[good], values[good])
        elif kind == PART_STATE_ARRAY:
            per_part = np.repeat(t, batch["parts._count"].astype(np.int64))
            on = batch["parts.on_track"].astype(bool)
            velocity = batch["parts.velocity_mps"]
            good = on & np.isfinite(velocity)
            self._count_bad("non-finite PartState.velocity_mps left out", on & ~good, velocity)
            self.add("gt_speed", per_part[good], velocity[good])
            self.add("gt_slip", per_part[on], (batch["parts.phase"][on] != 0).astype(np.float64))
        elif kind == PART_SENSOR_EVENT:
            self._sensor_events(t, batch)
        elif kind == PART_EXIT:
            self.add("exits", t, np.ones(len(t)))

    def _count_drive(self, freq: npt.NDArray[Any], amp: npt.NDArray[Any]) -> None:
        """Non-finite drive settings count as "off" (see ``_Timeline.add``): say so."""
        self._count_bad("non-finite drive amplitude(s) taken as off", ~np.isfinite(amp), amp)
        driven = np.isfinite(amp) & (amp != 0.0)
        self._count_bad(
            "non-finite drive frequency(ies) taken as off", driven & ~np.isfinite(freq), freq
        )

    def _count_bad(self, reason: str, bad: npt.NDArray[np.bool_], values: npt.NDArray[Any]) -> None:
        count = int(np.count_nonzero(bad))
        if count:
            self.leave_out(reason, count, repr(float(values[np.argmax(bad)])))

    def _state_batch(self, t: npt.NDArray[np.int64], batch: ColumnBatch) -> None:
        freq_cols, amp_cols = batch["drive_frequency_hz"], batch["drive_amplitude_n"]
        periods = np.asarray(batch["sample_period_s"], dtype=np.float64)
        # the estimator's limit: a period must be > 0 and at most 1 s (NaN, inf, ns sent as s...)
        bad = ~((periods > 0.0) & (periods <= MAX_SAMPLE_PERIOD_S))
        self._count_bad(
            "CarrierStateBatch message(s) with an impossible sample_period_s left out",
            bad,
            periods,
        )
        stamps, freqs, amps = [], [], []
        for k in np.flatnonzero(~bad).tolist():
            freq = np.asarray(freq_cols[k], dtype=np.float64)
            amp = np.asarray(amp_cols[k], dtype=np.float64)
            m = min(len(freq), len(amp))
            stamps.append(t[k] + np.round(np.arange(m) * float(periods[k]) * 1e9).astype(np.int64))
            freqs.append(freq[:m])
            amps.append(amp[:m])
        if stamps:
            all_t = np.concatenate(stamps)
            self.see(all_t)
            all_freq, all_amp = np.concatenate(freqs), np.concatenate(amps)
            self._count_drive(all_freq, all_amp)
            self.state.add(all_t, all_freq, all_amp)

    def _sensor_events(self, t: npt.NDArray[np.int64], batch: ColumnBatch) -> None:
        rising = batch["present"].astype(bool)
        order = np.argsort(t, kind="stable")
        out_t: list[int] = []
        out_v: list[float] = []
        sensors, positions, parts = (
            batch["sensor_index"],
            batch["sensor_position_m"],
            batch["part_id"],
        )
        for k in order:
            part = int(parts[k])
            if not rising[k] or part == 0:
                continue
            sensor, position, when = int(sensors[k]), float(positions[k]), int(t[k])
            previous = self.last_edge.get(part)
            self.last_edge[part] = (sensor, position, when)
            if previous is None or previous[0] == sensor or when <= previous[2]:
                continue
            distance = position - previous[1]
            if distance != 0.0 and math.isfinite(distance):
                out_t.append(when)
                out_v.append(distance / ((when - previous[2]) * 1e-9))
        self.add("sensor_speed", np.asarray(out_t, dtype=np.int64), np.asarray(out_v))


# ------------------------------------------------------------------------------- results


def _mean(acc: _Accumulator, metric: str, i: int) -> float:
    counts = acc.counts[metric]
    if i >= len(counts) or counts[i] == 0:
        return math.nan
    return float(acc.sums[metric][i] / counts[i])


def _count(acc: _Accumulator, metric: str, i: int) -> int:
    counts = acc.counts[metric]
    return int(counts[i]) if i < len(counts) else 0


def _segments(acc: _Accumulator, start: int, end: int, min_segment_s: float) -> list[Segment]:
    timeline = acc.timeline
    bounds = [start, *timeline.times, end]
    settings: list[Setting | None] = [None, *timeline.settings]
    out: list[Segment] = []
    for i, setting in enumerate(settings):
        lo, hi = bounds[i], bounds[i + 1]
        has_data = any(_count(acc, m, i) for m in METRICS)
        if i == 0 and (hi <= lo or not has_data):
            continue  # nothing before the first drive information
        duration = (hi - lo) * 1e-9
        exited = _count(acc, "exits", i)
        segment = Segment(
            index=len(out),
            start_s=(lo - start) * 1e-9,
            end_s=(hi - start) * 1e-9,
            frequency_hz=None if setting is None else setting[0],
            amplitude_n=None if setting is None else setting[1],
            speed_estimate_mps=_mean(acc, "est_speed", i),
            slip_estimate=_mean(acc, "est_slip", i),
            speed_ground_truth_mps=_mean(acc, "gt_speed", i),
            slip_ground_truth=_mean(acc, "gt_slip", i),
            speed_sensors_mps=_mean(acc, "sensor_speed", i),
            transits=_count(acc, "sensor_speed", i),
            parts_exited=exited,
            feed_rate_per_min=exited / (duration / 60.0) if duration > 0 else math.nan,
            transient=duration < min_segment_s,
        )
        out.append(segment)
    return out


def frequency_response(segments: Sequence[Segment]) -> list[FrequencyPoint]:
    """Operating points (amplitude, frequency) of the driven, settled segments; empty unless the
    bag holds at least two drive frequencies (a sweep)."""
    groups: dict[tuple[float, float], list[Segment]] = {}
    for s in segments:
        if s.enabled and not s.transient and s.frequency_hz is not None:
            assert s.amplitude_n is not None
            groups.setdefault((s.amplitude_n, s.frequency_hz), []).append(s)
    if len({f for _, f in groups}) < 2:
        return []

    def weighted(values: list[tuple[float, float]]) -> float:
        pairs = [(v, w) for v, w in values if not math.isnan(v)]
        total = sum(w for _, w in pairs)
        return sum(v * w for v, w in pairs) / total if total > 0 else math.nan

    points = []
    for (amp, freq), members in sorted(groups.items()):
        duration = sum(s.duration_s for s in members)
        exited = sum(s.parts_exited for s in members)
        points.append(
            FrequencyPoint(
                amplitude_n=amp,
                frequency_hz=freq,
                duration_s=duration,
                speed_mps=weighted([(s.speed_mps, s.duration_s) for s in members]),
                slip_fraction=weighted([(s.slip_fraction, s.duration_s) for s in members]),
                feed_rate_per_min=exited / (duration / 60.0) if duration > 0 else math.nan,
            )
        )
    return points


def _diagnostics(bag: Bag, start: int) -> tuple[list[DiagnosticChange], list[str]]:
    changes: list[DiagnosticChange] = []
    notes: list[str] = []
    levels: dict[str, int] = {}
    for raw in iter_messages(bag, types=[DIAGNOSTIC_ARRAY]):
        try:
            message = raw.decode()
        except (BagError, ValueError, IndexError, KeyError) as err:
            notes.append(f"undecodable diagnostics message on {raw.topic}: {err}")
            continue
        stamp = message["header"]["stamp"]
        t = stamp["sec"] * 1_000_000_000 + stamp["nanosec"] or raw.log_time_ns
        for status in message.get("status", []):
            level = status["level"]
            level = level[0] if isinstance(level, bytes | bytearray) else int(level)
            name = str(status["name"])
            if levels.get(name) == level:
                continue
            levels[name] = level
            if len(changes) >= _MAX_DIAG_CHANGES:
                notes.append(
                    f"more than {_MAX_DIAG_CHANGES} diagnostic level changes; rest left out"
                )
                return changes, notes
            changes.append(
                DiagnosticChange((t - start) * 1e-9, name, level, str(status["message"]))
            )
    return changes, notes


def analyze_bag(
    path: str | os.PathLike[str],
    *,
    min_segment_s: float = 0.5,
    progress: Progress | None = None,
) -> BagAnalysis:
    """Analyse one bag (directory or .mcap file). Raises ``AnalysisError`` (or another
    ``BagError``) when nothing could be analysed; problems the reader worked around are listed in
    ``BagAnalysis.problems``."""
    requests = dict(REQUESTS)
    left_out: list[str] = []
    while True:
        try:
            bag, acc, result = _main_pass(path, requests, progress)
            break
        except (KeyError, UnsupportedLayoutError) as err:
            # a feeder type recorded with another definition than ours: leave it out and start over
            kind = (
                err.type_name
                if isinstance(err, UnsupportedLayoutError)
                else str(err.args[0] if err.args else "").split(" ", 1)[0]
            )
            if kind not in requests:
                raise AnalysisError(Path(path), f"cannot decode a feeder type: {err}") from None
            del requests[kind]
            left_out.append(
                f"[foreign_definition] {kind} in the bag does not match feeder_ros's definition "
                f"({str(err).strip(chr(34) + chr(39))}); that type is left out"
            )
    result.problems.extend(left_out)
    # the channels the main pass met (all of them, not only the feeder types): a recorder killed
    # before it rewrote metadata.yaml leaves topics out of it, so the data decides
    seen_diagnostics = DIAGNOSTIC_ARRAY in bag.channel_types.values()
    start = acc.t_min
    result.problems.extend(acc.notes(start))
    diag: list[DiagnosticChange] = []
    if seen_diagnostics:
        diag_start = start if start is not None else 0
        diag_bag = Bag(bag.path, warn=False)
        diag, notes = _diagnostics(diag_bag, diag_start)
        result.problems.extend(notes)
        for problem in diag_bag.problems:  # e.g. a chunk of diagnostics only, skipped as corrupt
            if problem not in bag.problems:
                bag.report(problem)
        if diag and start is None:  # diagnostics only: times relative to the first diagnostics
            first = diag[0].t_s
            diag = [DiagnosticChange(d.t_s - first, d.name, d.level, d.message) for d in diag]
    result.problems[:0] = [str(p) for p in bag.problems]
    result.cut_short = bag.cut_short
    lost = bag.lost_data()
    result.data_losses = lost
    result.chunks_lost = sum(p.kind == "corrupt_chunk" for p in lost)
    result.lost_s = sum(p.lost_ns or 0 for p in lost) * 1e-9
    result.diagnostics = diag
    for kind, topics in result.topics.items():
        if len(topics) > 1:
            result.problems.append(
                f"[several_topics] {len(topics)} topics of type {kind} ({', '.join(topics)}); "
                "analysed together as one feeder"
            )
    if start is None or acc.t_max is None:
        if diag:
            result.drive_source = "none"
            return result
        reason = "no usable feeder data" if left_out else _no_data_reason(bag)
        raise AnalysisError(bag.path, "; ".join([reason, *left_out]))
    result.start_ns, result.end_ns = start, acc.t_max
    result.drive_source = (
        "carrier state" if acc.state.times else "drive command" if acc.command.times else "none"
    )
    segments = _segments(acc, start, acc.t_max, min_segment_s)
    result.transient_segments = sum(s.transient for s in segments)
    result.segments = [s for s in segments if not s.transient]
    for i, s in enumerate(result.segments):
        s.index = i
    result.frequency_response = frequency_response(result.segments)
    return result


_LOSS_WORDS = {
    "corrupt_chunk": "corrupt chunk(s) skipped",
    "corrupt_record": "damaged record(s) skipped over",
    "missing_file": "missing file(s)",
    "unreadable": "unreadable file(s)",
    "not_mcap": "file(s) that are not MCAP",
    "cut_short": "split file(s) cut short before the last",
    "malformed_message": "chunk(s) with malformed messages dropped",
    "unsupported_encoding": "chunk(s) with messages in an unknown encoding",
    "unknown_channel": "chunk(s) with messages of an undefined channel",
}


def _main_pass(
    path: str | os.PathLike[str],
    requests: dict[str, list[str]],
    progress: Progress | None,
) -> tuple[Bag, _Accumulator, BagAnalysis]:
    """The one pass over the bag: every batch of the requested types into the accumulator."""
    bag = Bag(path, warn=False)
    result = BagAnalysis(bag.path)
    acc = _Accumulator()
    span = _expected_span(bag)
    done = 0.0
    chunk: set[tuple[Path, str]] = set()  # (file, topic) of the batches of the current chunk
    for batch in read_tables(bag, requests):
        key = (batch.file, batch.topic)
        if key in chunk:  # a topic again: a new chunk began, the previous one is complete
            if acc.pending_count > _FLUSH_BATCH:
                acc.flush()
            chunk.clear()
        chunk.add(key)
        acc.batch(batch)
        if acc.pending_count > _PENDING_LIMIT:
            acc.flush()
        result.messages[batch.type] = result.messages.get(batch.type, 0) + len(batch)
        topics = result.topics.setdefault(batch.type, [])
        if batch.topic not in topics:
            topics.append(batch.topic)
        if progress is not None:
            done = _fraction(bag, batch, span, done)
            progress(done)
    acc.flush(final=True)
    return bag, acc, result


def _no_data_reason(bag: Bag) -> str:
    problems = list(bag.problems)
    kinds = {p.kind for p in problems}
    if "not_mcap" in kinds:
        return (
            "not an MCAP bag (" + "; ".join(str(p) for p in problems if p.kind == "not_mcap") + ")"
        )
    info = bag_info(Bag(bag.path, warn=False))
    if not info.topics:
        detail = "; ".join(str(p) for p in problems)
        return "empty bag: no messages" + (f" ({detail})" if detail else "")
    if info.message_count == 0:
        return "empty bag: topics " + ", ".join(sorted(info.topics)) + " but no messages"
    found = ", ".join(f"{t.name} ({t.type or 'no schema'})" for t in info.topics.values())
    unknown = [str(p) for p in problems if p.kind == "unknown_schema"]
    reason = f"no feeder topics (found {found})"
    if unknown:
        reason += "; " + "; ".join(unknown)
    return reason


def _expected_span(bag: Bag) -> tuple[int, int] | None:
    meta = bag.metadata or {}
    try:
        start = int(meta["starting_time"]["nanoseconds_since_epoch"])
        duration = int(meta["duration"]["nanoseconds"])
    except (KeyError, TypeError, ValueError):
        return None
    return (start, duration) if duration > 0 else None


def _fraction(bag: Bag, batch: ColumnBatch, span: tuple[int, int] | None, done: float) -> float:
    try:
        index = bag.files.index(batch.file)
    except ValueError:
        index = 0
    by_file = index / max(len(bag.files), 1)
    if span is not None and len(batch):
        by_time = (int(batch[LOG_TIME].max()) - span[0]) / span[1]
        return max(done, min(max(by_time, by_file), 1.0))
    return max(done, by_file)


def analyze_bags(
    paths: Sequence[str | os.PathLike[str]],
    *,
    min_segment_s: float = 0.5,
    progress: Callable[[int, float], None] | None = None,
) -> list[BagAnalysis]:
    """Analyse each bag; a bag that cannot be analysed gets ``error`` set instead of raising."""
    results = []
    for k, path in enumerate(paths):
        report = None if progress is None else (lambda f, k=k: progress(k, f))
        try:
            results.append(analyze_bag(path, min_segment_s=min_segment_s, progress=report))
        except (BagError, OSError) as err:
            results.append(BagAnalysis(Path(path), error=str(err)))
    return results
