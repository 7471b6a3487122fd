"""Per-feeder accumulation for :mod:`feeder_ros.bag.analysis`: the drive timeline (change points of
the drive setting) and per-segment sums of the metric samples, reduced as the bag streams by.

Metric samples wait in a small pending buffer until the drive timeline has passed their time, then
are reduced into per-segment sums (``np.bincount``); only change points and per-segment sums are
kept. A sensor transit (a part's rising edges at two sensors) counts only when its whole passage,
entry at the first sensor to arrival at the second, lies within one segment: one that entered
under the previous setting or during its ramp (the ramp's many short segments) would mix two speeds
(``Segment.transits_left_out`` counts those).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from feeder_ros.bag.feeders import (
    CARRIER_STATE,
    CARRIER_STATE_BATCH,
    DRIVE_COMMAND,
    PART_EXIT,
    PART_SENSOR_EVENT,
    PART_STATE_ARRAY,
    VEHICLE_ESTIMATE,
)
from feeder_ros.bag.reader import LOG_TIME, ColumnBatch
from feeder_ros.bag.results import Segment

__all__ = [
    "MAX_SAMPLE_PERIOD_S",
    "METRICS",
    "MIN_PHASE_BINS",
    "PENDING_LIMIT",
    "PHASE_BINS",
    "Accumulator",
    "Timeline",
    "segments",
]

#: the longest CarrierStateBatch sample period taken (the vehicle estimator node's limit) [s]
MAX_SAMPLE_PERIOD_S = 1.0
# per-segment sums and counts of: estimator mean speed and slip (status OK only), ground truth
# (each part's displacement and time between consecutive samples on the track; its slip flag per
# sample), sensor transit speeds, exits (value 1 each)
METRICS = ("est_speed", "est_slip", "gt_dx", "gt_dt", "gt_slip", "sensor_speed", "exits")
#: metric samples held before a forced flush
PENDING_LIMIT = 2_000_000
_COMMAND_MARGIN_NS = 2_000_000_000  # command-only bags: commands may be stamped this much late
#: the drive cycle's phase bins the part-state samples of a segment are sorted into, and how many
#: of them the samples must visit for the sampled slip fraction to be given (a slip or stick arc
#: is then resolved to a bin, 1/36 of the cycle, instead of to the sampled phases' spacing)
PHASE_BINS = 36
MIN_PHASE_BINS = 24

Setting = tuple[float, float]  # (frequency_hz, amplitude_n); (0, 0) is "off"
#: pending samples: times, values, and when each one's span began (None: at the sample)
Samples = tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64] | None]


def stamps(batch: ColumnBatch) -> npt.NDArray[np.int64]:
    t = batch["header.stamp.sec"].astype(np.int64) * 1_000_000_000 + batch[
        "header.stamp.nanosec"
    ].astype(np.int64)
    log = batch[LOG_TIME].astype(np.int64)
    return np.where(t == 0, log, t)


class Timeline:
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


class Accumulator:
    """Per-segment sums of metric samples; samples wait until the drive timeline passed them."""

    def __init__(self) -> None:
        self.state = Timeline()
        self.command = Timeline()
        #: per metric: batches of samples (``Samples``); a sensor transit spans from its entry
        self.pending: dict[str, list[Samples]] = {m: [] for m in METRICS}
        self.pending_count = 0
        self.sums: dict[str, npt.NDArray[np.float64]] = {m: np.zeros(0) for m in METRICS}
        self.counts: dict[str, npt.NDArray[np.float64]] = {m: np.zeros(0) for m in METRICS}
        #: per segment: samples left out because their span began in an earlier segment
        self.straddling: dict[str, npt.NDArray[np.float64]] = {m: np.zeros(0) for m in METRICS}
        self.t_min: int | None = None
        self.t_max: int | None = None
        self.last_edge: dict[int, tuple[int, float, int]] = {}  # part -> (sensor, position, t)
        self.last_place: dict[int, tuple[int, float]] = {}  # part on the track -> (t, position)
        #: values left out, by reason: (count, an example) for the problems list
        self.left_out: dict[str, tuple[int, str]] = {}
        #: per segment (driven): which of the drive cycle's PHASE_BINS the part states sampled
        self.phases_seen: dict[int, npt.NDArray[np.bool_]] = {}
        #: (start s, end s, why) of each segment whose sampled slip fraction is not given
        self.aliased: list[tuple[float, float, str]] = []

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
    def timeline(self) -> Timeline:
        return self.state if self.state.times else self.command

    def see(self, t: npt.NDArray[np.int64]) -> None:
        if len(t):
            lo, hi = int(t.min()), int(t.max())
            self.t_min = lo if self.t_min is None else min(self.t_min, lo)
            self.t_max = hi if self.t_max is None else max(self.t_max, hi)

    def add(
        self,
        metric: str,
        t: npt.NDArray[np.int64],
        v: npt.NDArray[Any],
        since: npt.NDArray[np.int64] | None = None,
    ) -> None:
        """Samples of ``metric`` at times ``t``; ``since``: when each one's span began (a sensor
        transit's entry): it counts only in a segment that holds its whole span."""
        if len(t):
            self.pending[metric].append((t, np.asarray(v, dtype=np.float64), since))
            self.pending_count += len(t)

    def flush(self, final: bool = False) -> None:
        """Reduce the pending samples the drive timeline has passed (called between chunks: every
        drive sample of the chunks read so far is in the timeline); all of them when ``final``."""
        if final or self.pending_count > PENDING_LIMIT:
            cutoff = None
        elif self.state.last_t is not None:
            cutoff = self.state.last_t
        elif self.t_max is not None:
            cutoff = self.t_max - _COMMAND_MARGIN_NS
        else:
            return
        times = np.asarray(self.timeline.times, dtype=np.int64)
        self.pending_count = 0
        for metric, parts in self.pending.items():
            if not parts:
                continue
            t = np.concatenate([p[0] for p in parts])
            v = np.concatenate([p[1] for p in parts])
            spans = [p[2] for p in parts if p[2] is not None]
            since = np.concatenate(spans) if len(spans) == len(parts) else None
            if cutoff is not None:
                now = t <= cutoff
                later = ~now
                if later.any():
                    rest = None if since is None else since[later]
                    self.pending[metric] = [(t[later], v[later], rest)]
                else:
                    self.pending[metric] = []
                self.pending_count += int(later.sum())
                t, v = t[now], v[now]
                since = None if since is None else since[now]
            else:
                self.pending[metric] = []
            if len(t):
                self._reduce(metric, times, t, v, since)

    def _reduce(
        self,
        metric: str,
        times: npt.NDArray[np.int64],
        t: npt.NDArray[np.int64],
        v: npt.NDArray[np.float64],
        since: npt.NDArray[np.int64] | None,
    ) -> None:
        """Add samples to the sums of their segments (by ``times``, the drive change points); a
        sample whose span began in an earlier segment to ``straddling`` instead."""
        seg = np.searchsorted(times, t, side="right")  # segment 0: before the first drive info
        if metric == "gt_slip":
            self._see_phases(times, seg, t)
        whole = (
            np.ones(len(t), dtype=bool)
            if since is None
            else np.searchsorted(times, since, side="right") == seg
        )
        n = len(times) + 1
        for target, weights, keep in (
            (self.sums, v, whole),
            (self.counts, None, whole),
            (self.straddling, None, ~whole),
        ):
            add = np.bincount(
                seg[keep], weights=None if weights is None else weights[keep], minlength=n
            )
            old = target[metric]
            if len(old) < n:
                old = np.concatenate([old, np.zeros(n - len(old))])
            old[: len(add)] += add
            target[metric] = old

    def _see_phases(
        self, times: npt.NDArray[np.int64], seg: npt.NDArray[np.int64], t: npt.NDArray[np.int64]
    ) -> None:
        """Mark the drive-cycle phases (from the segment's start) at which parts were sampled
        (one pass over the samples, however many segments they fall in)."""
        settings = np.asarray(self.timeline.settings, dtype=np.float64).reshape(-1, 2)
        driven = seg > 0
        seg, t = seg[driven], t[driven]
        frequency, amplitude = settings[seg - 1, 0], settings[seg - 1, 1]
        on = (frequency > 0.0) & (amplitude != 0.0)  # the drive off: no cycle to sample
        seg, t, frequency = seg[on], t[on], frequency[on]
        since = (t - times[seg - 1]).astype(np.float64) * 1e-9
        bins = np.floor(np.mod(since * frequency, 1.0) * PHASE_BINS).astype(np.int64)
        visited = np.unique(seg * PHASE_BINS + np.clip(bins, 0, PHASE_BINS - 1))
        for code in visited.tolist():
            i, k = divmod(code, PHASE_BINS)
            self.phases_seen.setdefault(i, np.zeros(PHASE_BINS, dtype=bool))[k] = True

    def sampled_slip(self, i: int) -> tuple[float, str | None]:
        """Segment ``i``'s ground-truth slip fraction (the share of part samples slipping), or
        NaN and why when the samples saw too few phases of the drive cycle to give it: at a
        rate commensurate with the drive (50 Hz states of a 30 Hz drive: 5 phases) the share is
        that of a few fixed phases, wrong by up to a fifth of the cycle."""
        value = _mean(self, "gt_slip", i)
        seen = self.phases_seen.get(i)
        if seen is None or math.isnan(value):
            return value, None
        count = int(seen.sum())
        if count >= MIN_PHASE_BINS:
            return value, None
        frequency = self.timeline.settings[i - 1][0]
        return math.nan, (
            f"the part states sampled {count} of {PHASE_BINS} phase bins of the {frequency:g} Hz "
            "drive cycle (a sample rate commensurate with the drive): their share slipping, "
            f"{value:.2f}, would be that of those phases only"
        )

    # -- per type -------------------------------------------------------------------------------

    def batch(self, batch: ColumnBatch) -> None:
        t = stamps(batch)
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
            self._part_steps(per_part, batch["parts.part_id"], batch["parts.position_m"], on)
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

    def _part_steps(
        self,
        t: npt.NDArray[np.int64],
        ids: npt.NDArray[Any],
        position: npt.NDArray[Any],
        on: npt.NDArray[np.bool_],
    ) -> None:
        """Each part's displacement between consecutive samples on the track (a step counts in
        the segment holding both its ends). The mean part speed is displacement over time, not
        the mean of the sampled velocities: a part's velocity swings within each drive cycle and
        samples at a rate near the drive frequency see only a few phases of it (50 Hz samples of
        a 30 Hz stick-slip cycle: 5 phases, a mean 12 % low in the demo's cell)."""
        x = np.asarray(position, dtype=np.float64)
        good = on & np.isfinite(x)
        self._count_bad("non-finite PartState.position_m left out", on & ~good, x)
        order = np.lexsort((t, ids))
        t, ids, x, good = t[order], np.asarray(ids)[order], x[order], good[order]
        n = len(t)
        if n == 0:
            return
        same = np.zeros(n, dtype=bool)
        same[1:] = ids[1:] == ids[:-1]
        prev_t = np.zeros(n, dtype=np.int64)
        prev_x = np.zeros(n)
        prev_ok = np.zeros(n, dtype=bool)
        prev_t[1:], prev_x[1:], prev_ok[1:] = t[:-1], x[:-1], good[:-1]
        for k in np.flatnonzero(~same).tolist():  # a part's first sample here: its last before
            stored = self.last_place.get(int(ids[k]))
            prev_ok[k] = stored is not None
            if stored is not None:
                prev_t[k], prev_x[k] = stored
        last = np.ones(n, dtype=bool)
        last[:-1] = ~same[1:]
        for k in np.flatnonzero(last).tolist():  # off the track (or no position): chain broken
            if good[k]:
                self.last_place[int(ids[k])] = (int(t[k]), float(x[k]))
            else:
                self.last_place.pop(int(ids[k]), None)
        step = good & prev_ok & (t > prev_t)
        since = prev_t[step]
        self.add("gt_dx", t[step], x[step] - prev_x[step], since)
        self.add("gt_dt", t[step], (t[step] - since) * 1e-9, since)

    def _sensor_events(self, t: npt.NDArray[np.int64], batch: ColumnBatch) -> None:
        rising = batch["present"].astype(bool)
        order = np.argsort(t, kind="stable")
        out_t: list[int] = []
        out_v: list[float] = []
        out_since: list[int] = []  # the entry at the first sensor
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
                out_since.append(previous[2])
        self.add(
            "sensor_speed",
            np.asarray(out_t, dtype=np.int64),
            np.asarray(out_v),
            np.asarray(out_since, dtype=np.int64),
        )


# ------------------------------------------------------------------------------- results


def _mean(acc: Accumulator, metric: str, i: int) -> float:
    counts = acc.counts[metric]
    if i >= len(counts) or counts[i] == 0:
        return math.nan
    return float(acc.sums[metric][i] / counts[i])


def _ratio(acc: Accumulator, numerator: str, denominator: str, i: int) -> float:
    """Sum of ``numerator`` over sum of ``denominator`` in segment ``i`` (NaN: none)."""
    below = acc.sums[denominator]
    if i >= len(below) or below[i] <= 0.0:
        return math.nan
    return float(acc.sums[numerator][i] / below[i])


def _count(acc: Accumulator, metric: str, i: int) -> int:
    counts = acc.counts[metric]
    return int(counts[i]) if i < len(counts) else 0


def _straddling(acc: Accumulator, metric: str, i: int) -> int:
    left = acc.straddling[metric]
    return int(left[i]) if i < len(left) else 0


def segments(acc: Accumulator, start: int, end: int, min_segment_s: float) -> list[Segment]:
    timeline = acc.timeline
    bounds = [start, *timeline.times, end]
    settings: list[Setting | None] = [None, *timeline.settings]
    out: list[Segment] = []
    acc.aliased = []  # this call's segments: found afresh each time
    for i, setting in enumerate(settings):
        lo, hi = bounds[i], bounds[i + 1]
        has_data = any(_count(acc, m, i) for m in METRICS)
        if i == 0 and (hi <= lo or not has_data):
            continue  # nothing before the first drive information
        duration = (hi - lo) * 1e-9
        exited = _count(acc, "exits", i)
        slip_truth, why = acc.sampled_slip(i)
        if why is not None and duration >= min_segment_s:
            acc.aliased.append(((lo - start) * 1e-9, (hi - start) * 1e-9, why))
        segment = Segment(
            index=len(out),
            start_s=(lo - start) * 1e-9,
            end_s=(hi - start) * 1e-9,
            frequency_hz=None if setting is None else setting[0],
            amplitude_n=None if setting is None else setting[1],
            speed_estimate_mps=_mean(acc, "est_speed", i),
            slip_estimate=_mean(acc, "est_slip", i),
            speed_ground_truth_mps=_ratio(acc, "gt_dx", "gt_dt", i),
            slip_ground_truth=slip_truth,
            speed_sensors_mps=_mean(acc, "sensor_speed", i),
            transits=_count(acc, "sensor_speed", i),
            transits_left_out=_straddling(acc, "sensor_speed", i),
            parts_exited=exited,
            feed_rate_per_min=exited / (duration / 60.0) if duration > 0 else math.nan,
            transient=duration < min_segment_s,
        )
        out.append(segment)
    return out
