"""What ``feeder analyze`` finds in a bag, per feeder: drive segments with their speeds, slip and
feed rate, diagnostic level changes, the frequency response, and what the bag lost.

Plain data (see :mod:`feeder_ros.bag.analysis` for how it is computed and
:mod:`feeder_ros.bag.report` for how it is shown); SI units, NaN where the bag has no source.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from feeder_ros.bag.errors import BagError, BagProblem
from feeder_ros.bag.feeders import namespace_slug, owner
from feeder_ros.bag.loss import LossCount

if TYPE_CHECKING:  # run_log reads stamps through the accumulator, which builds Segments
    from feeder_ros.bag.run_log import RunFigures, Series

__all__ = [
    "AnalysisError",
    "BagAnalysis",
    "DiagnosticChange",
    "FrequencyPoint",
    "Segment",
    "frequency_response",
]

_DIAG_LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


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
    drive information; ``transient``: shorter than the minimum segment length (ramps).
    ``speed_sensors_mps`` is the mean over the ``transits`` that passed both sensors within the
    segment; ``transits_left_out`` arrived in it but entered before it began (under the previous
    setting or its ramp)."""

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
    transits_left_out: int = 0
    parts_exited: int = 0
    feed_rate_per_min: float = math.nan
    transient: bool = False
    #: the speed monitor's target during the segment (``speed/status``; NaN: none set)
    target_speed_mps: float = math.nan

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
    """One feeder of one bag (a bag holding several feeders gives one each: ``namespace``)."""

    path: Path
    #: the feeder's namespace (None: no feeder topics, diagnostics only); ``feeders``: the
    #: namespaces of every feeder found in the bag (this one included)
    namespace: str | None = None
    feeders: list[str] = field(default_factory=list)
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
    #: the bag's recorded against its readable messages (the whole bag, every feeder's topics)
    loss: LossCount | None = None
    error: str | None = None
    #: the run as the cell saw it (``speed/status``, ``drive/state``): headline figures, and the
    #: two streams for the plots (None where the bag lacks them)
    figures: RunFigures | None = None
    speed_status: Series | None = None
    drive_state: Series | None = None

    @property
    def shared(self) -> bool:
        """The bag holds several feeders: this is one of them."""
        return len(self.feeders) > 1

    @property
    def name(self) -> str:
        """The bag's name, and the feeder's namespace when the bag holds several: file names."""
        base = self.path.name or str(self.path)
        return (
            f"{base}_{namespace_slug(self.namespace)}" if self.shared and self.namespace else base
        )

    @property
    def label(self) -> str:
        """The bag's path, and the feeder's namespace when the bag holds several: headings."""
        return f"{self.path} [{self.namespace}]" if self.shared else str(self.path)

    def owns(self, topic: str) -> bool:
        """``topic`` is this feeder's (under its namespace), or the bag holds one feeder."""
        return not self.shared or owner(topic, self.feeders) == self.namespace

    def feeder_loss(self) -> tuple[int, int]:
        """(lost, recorded) messages of this feeder's topics (those under its namespace)."""
        if self.loss is None or self.namespace is None:
            return 0, 0
        mine = [t for t in self.loss.topics if owner(t.topic, self.feeders) == self.namespace]
        return sum(t.lost for t in mine), sum(t.recorded for t in mine)

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
        """What was lost, in a few words: "400 of 5000 recorded messages lost, 2 corrupt chunk(s)
        skipped, 1 missing file(s), about 0.5 s of recording" (the count from ``loss``, the time
        when the files tell it); with several feeders, this feeder's share of the count."""
        words = []
        loss = self.loss
        if loss is not None and loss.lost:
            words.append(
                f"{loss.lost} of {loss.recorded} recorded messages lost"
                if loss.exact
                else f"at least {loss.lost} recorded messages lost (how many were recorded is "
                "unknown)"
            )
            if self.shared:
                lost, recorded = self.feeder_loss()
                words[-1] += f" ({lost} of {recorded} of this feeder's)"
        counts: dict[str, int] = {}
        for problem in self.data_losses:
            if problem.kind != "lost_messages":
                counts[problem.kind] = counts.get(problem.kind, 0) + 1
        words += [
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
        lost, recorded = self.feeder_loss()
        return {
            "bag": str(self.path),
            "namespace": self.namespace,
            "feeders_in_bag": list(self.feeders),
            "error": self.error,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "duration_s": self.duration_s,
            "cut_short": self.cut_short,
            "data_losses": [str(p) for p in self.data_losses],
            "chunks_lost": self.chunks_lost,
            "lost_s": self.lost_s,
            "lost_messages": None if self.loss is None else self.loss.lost,
            "loss": None if self.loss is None else self.loss.as_dict(),
            "feeder_lost_messages": {"lost": lost, "recorded": recorded},
            "drive_source": self.drive_source,
            "messages": dict(self.messages),
            "topics": {k: list(v) for k, v in self.topics.items()},
            "totals": self.totals(),
            "headline": None if self.figures is None else _figures_dict(self.figures),
            "transient_segments": self.transient_segments,
            "segments": [s.as_dict() for s in self.segments],
            "frequency_response": [asdict(p) for p in self.frequency_response],
            "diagnostics": [{**asdict(d), "level_name": d.level_name} for d in self.diagnostics],
            "problems": list(self.problems),
        }


def _figures_dict(figures: RunFigures) -> dict[str, Any]:
    data = asdict(figures)
    data["at_target_share"] = figures.at_target_share
    data["faults"] = [{**asdict(f), "duration_s": f.duration_s} for f in figures.faults]
    return data


_LOSS_WORDS = {
    "corrupt_chunk": "corrupt chunk(s) skipped",
    "corrupt_record": "damaged record(s) skipped over",
    "missing_file": "missing file(s)",
    "unreadable": "unreadable file(s)",
    "not_mcap": "file(s) that are not MCAP",
    "cut_short": "split file(s) cut short before the last",
    "cut_chunk": "chunk(s) cut off by the end of a file",
    "malformed_message": "chunk(s) with malformed messages dropped",
    "unsupported_encoding": "chunk(s) with messages in an unknown encoding",
    "unknown_channel": "chunk(s) with messages of an undefined channel",
}


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
