"""Streaming analysis of feeder bags: drive segments, part speed, slip, feed rate, diagnostics.

ROS free: reads bags with :func:`~feeder_ros.bag.read_tables` (one pass, column batches chunk by
chunk) and, when the bag holds ``diagnostic_msgs/DiagnosticArray``, a second pass over those
messages only. Topics are recognised by TYPE, so namespaced or remapped feeder topics are found and
unrelated topics are ignored.

Several feeders in one bag (``feeder record`` of a whole cell) are told apart by namespace
(:mod:`feeder_ros.bag.feeders`: ``/feeder_a/carrier/state`` and ``/feeder_b/carrier/state``) and
analysed each on its own, in the same pass: one :class:`BagAnalysis` per feeder
(:func:`analyze_feeders`; ``namespace`` picks one). Several topics of one type within one feeder
are analysed together (and reported as a problem).

Time axis: every message's ``header.stamp`` (the feeder's own clock; the log time where a stamp is
zero). Segments of constant drive setting (frequency, amplitude; "off" when the amplitude is zero or
the drive disabled) come from ``CarrierState``/``CarrierStateBatch`` (the drive actually applied)
or, in bags without carrier state, from ``DriveCommand``. A segment runs from the first sample with
its setting to the first sample with the next one.

Per segment: mean part speed from the estimator (``VehicleEstimate.mean_speed_mps``, samples with
status OK), from ground truth (``PartStateArray``: the parts' displacement on the track over their
time on it, see ``Accumulator._part_steps``) and
from part-present sensor transits (``PartSensorEvent`` rising edges of one part at two sensors:
distance over time; only transits whose whole passage lies within the segment, see
:mod:`feeder_ros.bag.accumulator`); slip fraction from the estimator and from the ground-truth
phases; feed rate from ``PartExit``. Segments shorter than ``min_segment_s`` (ramps) are counted as
transient and left out. ``DiagnosticArray`` is decoded message by message (its ``KeyValue[]``
inside ``status[]`` does not fit the column decoder).

What the bag lost is counted by the reader (``Bag.loss``: recorded against readable messages, per
topic) and reported with every feeder of the bag (``BagAnalysis.loss``, ``data_losses``).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from feeder_ros.bag import run_log
from feeder_ros.bag.accumulator import PENDING_LIMIT, Accumulator, segments
from feeder_ros.bag.errors import BagError, UnsupportedLayoutError
from feeder_ros.bag.feeders import (
    CARRIER_STATE,
    CARRIER_STATE_BATCH,
    DIAGNOSTIC_ARRAY,
    DRIVE_COMMAND,
    PART_EXIT,
    PART_SENSOR_EVENT,
    PART_STATE_ARRAY,
    VEHICLE_ESTIMATE,
    FeederGroups,
    Router,
    group_feeders,
    normalize_namespace,
    owner,
)
from feeder_ros.bag.reader import LOG_TIME, Bag, ColumnBatch, bag_info, iter_messages, read_tables
from feeder_ros.bag.results import (
    AnalysisError,
    BagAnalysis,
    DiagnosticChange,
    FrequencyPoint,
    Segment,
    frequency_response,
)
from feeder_ros.bag.run_log import DRIVE_STATE, SPEED_STATUS, RunLog, run_figures, targets

__all__ = [
    "FEEDER_TYPES",
    "AnalysisError",
    "BagAnalysis",
    "DiagnosticChange",
    "FrequencyPoint",
    "Segment",
    "analyze_bag",
    "analyze_bags",
    "analyze_feeders",
    "frequency_response",
]

_STAMP = ["header.stamp.sec", "header.stamp.nanosec"]
REQUESTS: dict[str, list[str]] = {
    DRIVE_COMMAND: [*_STAMP, "enabled", "frequency_hz", "amplitude_n"],
    CARRIER_STATE: [*_STAMP, "drive_frequency_hz", "drive_amplitude_n"],
    CARRIER_STATE_BATCH: [*_STAMP, "sample_period_s", "drive_frequency_hz", "drive_amplitude_n"],
    VEHICLE_ESTIMATE: [*_STAMP, "mean_speed_mps", "slip_fraction", "status"],
    PART_STATE_ARRAY: [
        *_STAMP,
        "parts.part_id",
        "parts.position_m",
        "parts.phase",
        "parts.on_track",
    ],
    PART_SENSOR_EVENT: [*_STAMP, "sensor_index", "sensor_position_m", "part_id", "present"],
    PART_EXIT: [*_STAMP, "part_id"],
    **run_log.REQUESTS,
}
FEEDER_TYPES = frozenset([*REQUESTS, DIAGNOSTIC_ARRAY])

_MAX_DIAG_CHANGES = 10_000
_FLUSH_BATCH = 100_000  # metric samples gathered before they are reduced (between chunks)

Progress = Callable[[float], None]


@dataclass
class _FeederRun:
    """One feeder's accumulation during the pass, and what it read."""

    acc: Accumulator = field(default_factory=Accumulator)
    log: RunLog = field(default_factory=RunLog)  # speed status and drive state over time
    messages: dict[str, int] = field(default_factory=dict)  # per feeder type
    topics: dict[str, list[str]] = field(default_factory=dict)  # type -> topics


@dataclass
class _Pass:
    bag: Bag
    router: Router
    runs: dict[str, _FeederRun]


def _main_pass(
    path: str | os.PathLike[str],
    requests: dict[str, list[str]],
    fixed: FeederGroups | None,
    namespace: str | None,
    progress: Progress | None,
) -> _Pass:
    """The one pass over the bag: every batch of the requested types into its feeder's
    accumulator (``namespace``: only that feeder's)."""
    bag = Bag(path, warn=False)
    router = Router(fixed)
    runs: dict[str, _FeederRun] = {}
    span = _expected_span(bag)
    done = 0.0
    chunk: set[tuple[Path, str]] = set()  # (file, topic) of the batches of the current chunk
    for batch in read_tables(bag, requests):
        key = (batch.file, batch.topic)
        if key in chunk:  # a topic again: a new chunk began, the previous one is complete
            for run in runs.values():
                if run.acc.pending_count > _FLUSH_BATCH:
                    run.acc.flush()
            chunk.clear()
        chunk.add(key)
        feeder = router(batch.topic, batch.type)
        if feeder is not None and (namespace is None or feeder == namespace):
            run = runs.setdefault(feeder, _FeederRun())
            run.acc.batch(batch)
            run.log.add(batch)
            if run.acc.pending_count > PENDING_LIMIT:
                run.acc.flush()
            run.messages[batch.type] = run.messages.get(batch.type, 0) + len(batch)
            topics = run.topics.setdefault(batch.type, [])
            if batch.topic not in topics:
                topics.append(batch.topic)
        if progress is not None:
            done = _fraction(bag, batch, span, done)
            progress(done)
    for run in runs.values():
        run.acc.flush(final=True)
    return _Pass(bag, router, runs)


def _read(
    path: str | os.PathLike[str], namespace: str | None, progress: Progress | None
) -> tuple[_Pass, list[str]]:
    """The main pass, repeated when it must be: without a feeder type recorded with another
    definition than ours (that type left out: the notes returned), and with the feeder groups of
    all the topics when a topic went to another feeder before they were all known."""
    requests = dict(REQUESTS)
    left_out: list[str] = []
    fixed: FeederGroups | None = None
    while True:
        try:
            read = _main_pass(path, requests, fixed, namespace, progress)
        except (KeyError, UnsupportedLayoutError) as err:
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
            continue
        regroup = read.router.settled()
        if regroup is None or fixed is not None:
            return read, left_out
        fixed = regroup


def _diagnostics(
    bag: Bag, starts: Mapping[str | None, int], feeders: Sequence[str]
) -> tuple[dict[str | None, list[DiagnosticChange]], list[str]]:
    """Level changes of the diagnostic statuses per feeder of ``starts`` (times from its start):
    with several feeders in the bag, a status named under a feeder's namespace is that feeder's
    and one named otherwise every feeder's."""
    changes: dict[str | None, list[DiagnosticChange]] = {ns: [] for ns in starts}
    levels: dict[str | None, dict[str, int]] = {ns: {} for ns in starts}
    notes: list[str] = []
    full: set[str | None] = set()
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
            holder = owner(name, feeders) if len(feeders) > 1 else None
            for ns in list(starts) if holder is None else [holder] if holder in starts else []:
                if levels[ns].get(name) == level or ns in full:
                    continue
                levels[ns][name] = level
                if len(changes[ns]) >= _MAX_DIAG_CHANGES:
                    full.add(ns)
                    notes.append(
                        f"more than {_MAX_DIAG_CHANGES} diagnostic level changes"
                        + (f" of {ns}" if ns else "")
                        + "; rest left out"
                    )
                    continue
                changes[ns].append(
                    DiagnosticChange((t - starts[ns]) * 1e-9, name, level, str(status["message"]))
                )
    return changes, notes


def _base(read: _Pass, namespace: str | None, feeders: list[str]) -> BagAnalysis:
    """A feeder's result with what the bag says: its problems, cut short, what it lost."""
    bag = read.bag
    lost = bag.lost_data()
    return BagAnalysis(
        bag.path,
        namespace=namespace,
        feeders=list(feeders),
        problems=[str(p) for p in bag.problems],
        cut_short=bag.cut_short,
        data_losses=lost,
        chunks_lost=sum(p.kind == "corrupt_chunk" for p in lost),
        lost_s=sum(p.lost_ns or 0 for p in lost) * 1e-9,
        loss=bag.loss,
    )


def _feeder_result(
    result: BagAnalysis, run: _FeederRun, diagnostics: list[DiagnosticChange], min_segment_s: float
) -> BagAnalysis:
    """Fill one feeder's result from its run (which has data: ``acc.t_min`` is set)."""
    acc = run.acc
    assert acc.t_min is not None
    assert acc.t_max is not None
    result.messages, result.topics = run.messages, run.topics
    result.diagnostics = diagnostics
    where = f" under {result.namespace}" if result.shared else ""
    for kind, topics in run.topics.items():
        if len(topics) > 1:
            result.problems.append(
                f"[several_topics] {len(topics)} topics of type {kind}{where} "
                f"({', '.join(topics)}); analysed together as one feeder"
            )
    result.start_ns, result.end_ns = acc.t_min, acc.t_max
    result.drive_source = (
        "carrier state" if acc.state.times else "drive command" if acc.command.times else "none"
    )
    found = segments(acc, acc.t_min, acc.t_max, min_segment_s)
    if acc.aliased:
        lo, hi, why = acc.aliased[0]
        result.problems.append(
            f"[aliased] no ground-truth slip fraction in {len(acc.aliased)} segment(s) "
            f"(the first at {lo:.6g}-{hi:.6g} s: {why}); the truth's speed is unaffected; "
            "record part states faster, or at a rate no simple multiple of the drive's"
        )
    spans = [(s.start_s, s.end_s) for s in found]
    for s, target in zip(found, targets(run.log, spans, acc.t_min), strict=True):
        s.target_speed_mps = target
    fed = sum(s.parts_exited for s in found)  # ramps' exits too
    result.figures = run_figures(run.log, acc.t_min, acc.t_max, fed)
    result.speed_status = run.log.series(SPEED_STATUS)
    result.drive_state = run.log.series(DRIVE_STATE)
    result.transient_segments = sum(s.transient for s in found)
    result.segments = [s for s in found if not s.transient]
    for i, s in enumerate(result.segments):
        s.index = i
    result.frequency_response = frequency_response(result.segments)
    return result


def analyze_feeders(
    path: str | os.PathLike[str],
    *,
    min_segment_s: float = 0.5,
    namespace: str | None = None,
    progress: Progress | None = None,
) -> list[BagAnalysis]:
    """Analyse every feeder of one bag (directory or .mcap file), or only the one under
    ``namespace``: one result per feeder, in namespace order (one for a bag of one feeder; a
    feeder without usable data gets ``error`` set). Raises ``AnalysisError`` (or another
    ``BagError``) when nothing could be analysed; problems the reader worked around are listed in
    each result's ``problems``."""
    wanted = None if namespace is None else normalize_namespace(namespace)
    read, left_out = _read(path, wanted, progress)
    bag = read.bag
    groups = group_feeders(read.router.types)
    feeders = groups.namespaces
    if wanted is not None and wanted not in feeders:
        raise AnalysisError(
            bag.path,
            f"no feeder under namespace {wanted} (feeders found: {', '.join(feeders) or 'none'})",
        )
    notes = [*left_out]
    if groups.unassigned:
        notes.append(
            f"[unassigned_topics] {', '.join(groups.unassigned)} belong to none of the feeders "
            f"{', '.join(feeders)} (no feeder namespace holds them); left out"
        )
    starts: dict[str | None, int] = {
        ns: run.acc.t_min for ns, run in read.runs.items() if run.acc.t_min is not None
    }
    diagnostics: dict[str | None, list[DiagnosticChange]] = {}
    # the channels the main pass met (all of them, not only the feeder types): a recorder killed
    # before it rewrote metadata.yaml leaves topics out of it, so the data decides
    if DIAGNOSTIC_ARRAY in bag.channel_types.values():
        diag_bag = Bag(bag.path, warn=False)
        diagnostics, diag_notes = _diagnostics(diag_bag, starts or {None: 0}, feeders)
        notes += diag_notes
        for problem in diag_bag.problems:  # e.g. a chunk of diagnostics only, skipped as corrupt
            if problem not in bag.problems:
                bag.report(problem)
    results: list[BagAnalysis] = []
    for ns, run in sorted(read.runs.items()):
        result = _base(read, ns, feeders)
        result.problems += notes + run.acc.notes(run.acc.t_min)
        if ns in starts:
            results.append(_feeder_result(result, run, diagnostics.get(ns, []), min_segment_s))
            continue
        reason = "; ".join(["no usable feeder data", *left_out])
        if len(read.runs) == 1:
            raise AnalysisError(bag.path, reason)
        result.error = f"{bag.path} [{ns}]: {reason}"
        results.append(result)
    if results:
        return results
    diag = diagnostics.get(None, [])
    if not diag:
        reason = "no usable feeder data" if left_out else _no_data_reason(bag)
        raise AnalysisError(bag.path, "; ".join([reason, *left_out]))
    first = diag[0].t_s  # diagnostics only: times relative to the first diagnostics
    result = _base(read, None, feeders)
    result.problems += notes
    result.diagnostics = [DiagnosticChange(d.t_s - first, d.name, d.level, d.message) for d in diag]
    return [result]


def analyze_bag(
    path: str | os.PathLike[str],
    *,
    min_segment_s: float = 0.5,
    namespace: str | None = None,
    progress: Progress | None = None,
) -> BagAnalysis:
    """Analyse the one feeder of a bag (or the one under ``namespace``); see
    :func:`analyze_feeders`. A bag holding several feeders raises ``AnalysisError`` naming them
    unless ``namespace`` picks one."""
    results = analyze_feeders(
        path, min_segment_s=min_segment_s, namespace=namespace, progress=progress
    )
    if len(results) > 1:
        raise AnalysisError(
            results[0].path,
            f"{len(results)} feeders in one bag ({', '.join(r.namespace or '-' for r in results)})"
            ": analyse one at a time (namespace=NS; `feeder analyze --namespace NS`)",
        )
    return results[0]


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
    namespace: str | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> list[BagAnalysis]:
    """Analyse each bag: one result per feeder of each (``namespace``: only that feeder); a bag
    that cannot be analysed gets one result with ``error`` set instead of raising."""
    results: list[BagAnalysis] = []
    for k, path in enumerate(paths):
        report = None if progress is None else (lambda f, k=k: progress(k, f))
        try:
            results += analyze_feeders(
                path, min_segment_s=min_segment_s, namespace=namespace, progress=report
            )
        except (BagError, OSError) as err:
            results.append(BagAnalysis(Path(path), namespace=namespace, error=str(err)))
    return results
