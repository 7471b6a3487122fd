"""Streaming reader of rosbag2 MCAP bags: column batches for analysis, raw messages, bag info.

``Bag(path)`` accepts a bag directory (with or without ``metadata.yaml``) or a single ``.mcap``
file. Nothing loads a whole file: ``read_columns`` yields one batch of numpy columns per chunk and
topic, ``iter_messages`` one message at a time. Topics are matched by message TYPE (schema name), so
namespaced or remapped topics are found; other channels in a chunk are not decoded at all, and
chunks without a wanted channel are not even decompressed.

Problems (cut-short files, corrupt chunks, missing metadata, unknown schemas, malformed messages)
are appended to ``Bag.problems`` and issued as ``BagWarning``; reading carries on with what is
usable.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Collection, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from feeder_ros.bag.cdr import ColumnPlan, decode_cdr
from feeder_ros.bag.errors import (
    DATA_LOSS_KINDS,
    BagError,
    BagProblem,
    BagWarning,
    MessageDefinitionError,
    MissingBagError,
    UnsupportedLayoutError,
)
from feeder_ros.bag.loss import FileCount, LossCount, count_loss, file_count
from feeder_ros.bag.msgdef import MsgDefs, normalize_type, parse_ros2msg_schema
from feeder_ros.bag.scan import ChannelInfo, ChunkData, FileScan, ScanTally
from feeder_ros.bag.schemas import installed_definitions

__all__ = [
    "Bag",
    "BagInfo",
    "Checks",
    "ColumnBatch",
    "RawMessage",
    "TopicInfo",
    "bag_info",
    "concat_batches",
    "data_lost",
    "iter_messages",
    "read_columns",
    "read_tables",
]

LOG_TIME = "_log_time_ns"
PUBLISH_TIME = "_publish_time_ns"


def _listed_duration_ns(info: Mapping[str, Any], name: str) -> int | None:
    """The recording time metadata.yaml gives for the file ``name`` (None: not given)."""
    try:
        for entry in info.get("files") or []:
            if Path(str(entry["path"])).name == name:
                duration = int(entry["duration"]["nanoseconds"])
                return duration if duration > 0 else None
    except (KeyError, TypeError, ValueError, AttributeError):
        pass
    return None


def _file_index(path: Path) -> tuple[int, str]:
    match = re.search(r"_(\d+)\.mcap$", path.name)
    return (int(match[1]) if match else -1, path.name)


class Bag:
    """A bag directory or a single MCAP file, opened for streaming reads.

    ``warn``: also issue each problem as a ``BagWarning``. ``verify_crc``: check the CRC of every
    decompressed chunk (about 10 % of the decoding time) unless its zstd frame carries a checksum,
    which zstd verifies anyway (BagWriter writes one).
    """

    def __init__(
        self, path: str | os.PathLike[str], *, warn: bool = True, verify_crc: bool = True
    ) -> None:
        self.path = Path(path)
        if self.path.name == "metadata.yaml":
            self.path = self.path.parent
        self.warn = warn
        self.verify_crc = verify_crc
        self.problems: list[BagProblem] = []
        self.metadata: dict[str, Any] | None = None
        self.cut_short = False
        #: topic -> type of every channel met by a scan that has been read to its end
        self.channel_types: dict[str, str] = {}
        #: recorded against readable messages, counted by the last pass read to its end (None
        #: before one); a count that shows lost messages is also reported (``lost_messages``)
        self.loss: LossCount | None = None
        #: what each file's scan of that pass met and checked
        self.tallies: list[ScanTally] = []
        self._defs: dict[tuple[str, str], MsgDefs | None] = {}
        self._plans: dict[tuple[str, str], ColumnPlan] = {}
        if self.path.is_file():
            self.files = [self.path]
        elif self.path.is_dir():
            self.files = self._resolve_dir()
        else:
            raise MissingBagError(self.path, "no such file or directory")

    def _resolve_dir(self) -> list[Path]:
        found = sorted(self.path.glob("*.mcap"), key=_file_index)
        meta_path = self.path / "metadata.yaml"
        if not meta_path.is_file():
            if not found:
                raise MissingBagError(
                    self.path, "no metadata.yaml and no .mcap file in the directory"
                )
            self.report(
                BagProblem(
                    "missing_metadata",
                    meta_path,
                    f"no metadata.yaml; reading the {len(found)} .mcap file(s) found",
                )
            )
            return found
        try:
            data = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
            info = data["rosbag2_bagfile_information"]
            names = info.get("relative_file_paths") or []
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise ValueError(f"relative_file_paths is not a list of file names: {names!r}")
            listed = [self.path / Path(n).name for n in names]
            storage = info.get("storage_identifier", "")
        except (OSError, ValueError, yaml.YAMLError, KeyError, TypeError) as err:
            self.report(
                BagProblem(
                    "bad_metadata", meta_path, f"unreadable ({err}); using the .mcap files found"
                )
            )
            return found
        self.metadata = info
        if storage != "mcap":
            raise BagError(
                f"{meta_path}: storage_identifier {storage!r} is not supported (only mcap)"
            )
        files = [p for p in listed if p.is_file()]
        for p in listed:
            if not p.is_file():
                self.report(
                    BagProblem(
                        "missing_file",
                        p,
                        "listed in metadata.yaml but not present",
                        lost_ns=_listed_duration_ns(info, p.name),
                    )
                )
        for p in found:
            if p not in files:
                self.report(
                    BagProblem("unlisted_file", p, "not listed in metadata.yaml; read as well")
                )
                files.append(p)
        return sorted(files, key=_file_index)

    def lost_data(self) -> list[BagProblem]:
        """The problems found so far that mean recorded messages could not be read (see
        ``DATA_LOSS_KINDS``), and a file cut short that is not the bag's last: a killed recorder
        cuts only its last file short, so an earlier one lost its end while the recording went
        on."""
        return data_lost(self.problems, self.files)

    def report(self, problem: BagProblem) -> None:
        self.problems.append(problem)
        if problem.kind == "cut_short":
            self.cut_short = True
        if self.warn:
            warnings.warn(str(problem), BagWarning, stacklevel=3)

    def scans(self) -> Iterator[FileScan]:
        """One scan per file, in order; after a scan has been read, its channels are added to
        ``channel_types``. When every scan has been read to its end, the messages found are
        compared with what the bag says was recorded (``loss``)."""
        counts: list[FileCount] = []
        tallies: list[ScanTally] = []
        for path in self.files:
            scan = FileScan(path, self.report, self.verify_crc)
            yield scan
            for channel in scan.channels.values():
                self.channel_types.setdefault(channel.topic, channel.type)
            counts.append(file_count(scan))
            tallies.append(scan.tally)
        self.tallies = tallies
        missing = [p.file for p in self.problems if p.kind == "missing_file" and p.file]
        self.loss = count_loss(self.metadata, counts, missing)
        problem = self.loss.problem()
        if problem is not None and problem not in self.problems:
            self.report(problem)

    def definitions(self, channel: ChannelInfo) -> MsgDefs | None:
        """Parsed definitions for a channel: its ros2msg schema, else the installed .msg files."""
        key = (channel.type, channel.schema_text)
        if key in self._defs:
            return self._defs[key]
        defs: MsgDefs | None = None
        errors: list[str] = []
        if channel.schema_encoding == "ros2msg" and channel.schema_text.strip():
            try:
                defs = parse_ros2msg_schema(channel.type, channel.schema_text)
            except MessageDefinitionError as err:
                errors.append(str(err))
        if defs is None and channel.type:
            try:
                defs = installed_definitions(channel.type)
            except (MessageDefinitionError, OSError) as err:
                errors.append(str(err))
        if defs is None:
            self.report(
                BagProblem(
                    "unknown_schema",
                    None,
                    f"cannot decode type {channel.type or '(no schema)'}: "
                    f"{'; '.join(errors) or 'no schema'}",
                    topic=channel.topic,
                )
            )
        self._defs[key] = defs
        return defs

    def plan(self, channel: ChannelInfo) -> ColumnPlan | None:
        key = (channel.type, channel.schema_text)
        plan = self._plans.get(key)
        if plan is None:
            defs = self.definitions(channel)
            if defs is None:
                return None
            plan = ColumnPlan(defs, channel.type)
            self._plans[key] = plan
        return plan


def _as_bag(bag: Bag | str | os.PathLike[str]) -> Bag:
    return bag if isinstance(bag, Bag) else Bag(bag)


@dataclass
class ColumnBatch:
    """Columns of the messages of one topic in one chunk; ``_log_time_ns`` and ``_publish_time_ns``
    are added to the message fields."""

    topic: str
    type: str
    file: Path
    columns: dict[str, npt.NDArray[Any]]

    def __getitem__(self, name: str) -> npt.NDArray[Any]:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns[LOG_TIME])


def read_columns(
    bag: Bag | str | os.PathLike[str],
    type_name: str,
    fields: Collection[str] | None = None,
    *,
    topics: Collection[str] | None = None,
) -> Iterator[ColumnBatch]:
    """Batches of numpy columns of every message of ``type_name`` (on any topic, or ``topics``).

    ``fields`` selects columns by dotted path (a prefix selects everything below it); None: all.
    Column naming (ragged columns of sequences of messages included): see ``ColumnPlan``. Raises
    ``UnsupportedLayoutError`` for wstrings and sequences nested in sequences of messages (use
    ``iter_messages``) and ``KeyError`` for an unknown field.
    """
    return read_tables(bag, {type_name: fields}, topics=topics)


def read_tables(
    bag: Bag | str | os.PathLike[str],
    requests: Mapping[str, Collection[str] | None],
    *,
    topics: Collection[str] | None = None,
) -> Iterator[ColumnBatch]:
    """``read_columns`` for several types in ONE pass over the bag: ``requests`` maps each type to
    its fields (None: all). Batches of different types come interleaved; use ``batch.type``."""
    bag = _as_bag(bag)
    targets = {normalize_type(t): f for t, f in requests.items()}
    topic_set = None if topics is None else set(topics)

    def want(channel: ChannelInfo) -> bool:
        return (
            channel.type in targets
            and channel.message_encoding == "cdr"
            and (topic_set is None or channel.topic in topic_set)
        )

    selections: dict[int, frozenset[str]] = {}
    for scan in bag.scans():
        for chunk in scan.chunks(want):
            assert chunk.buf is not None
            for cid in chunk.records:
                channel = scan.channels[cid]
                plan = bag.plan(channel)
                if plan is None:
                    continue
                wanted = selections.get(id(plan))
                if wanted is None:
                    wanted = plan.select(targets[channel.type])
                    selections[id(plan)] = wanted
                yield from _decode_batch(bag, chunk, channel, plan, wanted)


def _decode_batch(
    bag: Bag,
    chunk: ChunkData,
    channel: ChannelInfo,
    plan: ColumnPlan,
    wanted: frozenset[str],
) -> Iterator[ColumnBatch]:
    buf = chunk.buf
    assert buf is not None
    cid = channel.id
    starts, ends = chunk.data_bounds(cid)
    short = starts + 4 > ends
    head = np.ndarray((len(buf) - 1,), dtype="<u2", buffer=buf, strides=(1,))[
        np.where(short, 0, starts)
    ]  # encapsulation id read little endian: 0x0100 is CDR_LE, 0x0000 CDR_BE
    little = (head == 0x0100) & ~short
    groups: list[tuple[str, npt.NDArray[np.int64] | None]] = [("<", None)]
    if not little.all():
        big = (head == 0) & ~short
        groups = [(o, np.flatnonzero(m)) for o, m in (("<", little), (">", big)) if m.any()]
        other = len(starts) - int(np.count_nonzero(little | big))
        if other:
            bag.report(
                BagProblem(
                    "unsupported_encoding",
                    chunk.file,
                    f"{other} message(s) without a plain CDR header; skipped",
                    chunk.offset,
                    channel.topic,
                )
            )
    for order, sel in groups:
        rows: slice | npt.NDArray[np.int64] = slice(None) if sel is None else sel
        cols, ok = plan.decode(buf, starts[rows], ends[rows], wanted, order)
        if not ok.all():
            bag.report(
                BagProblem(
                    "malformed_message",
                    chunk.file,
                    f"{int((~ok).sum())} {channel.type} message(s) end before their last field; "
                    "dropped",
                    chunk.offset,
                    channel.topic,
                )
            )
            masks = {c: np.repeat(ok, cols[c]) for c in set(plan.ragged.values()) & cols.keys()}
            cols = {
                k: v[masks[plan.ragged[k]]] if k in plan.ragged else v[ok] for k, v in cols.items()
            }
            rows = np.flatnonzero(ok) if sel is None else sel[ok]
        cols[LOG_TIME] = chunk.log_times[cid][rows]
        cols[PUBLISH_TIME] = chunk.publish_times[cid][rows]
        yield ColumnBatch(channel.topic, channel.type, chunk.file, cols)


def concat_batches(batches: Iterable[ColumnBatch]) -> dict[str, npt.NDArray[Any]]:
    """Concatenate batches into one dict of columns (loads everything: for tests and small bags)."""
    parts: dict[str, list[npt.NDArray[Any]]] = {}
    for batch in batches:
        for name, col in batch.columns.items():
            parts.setdefault(name, []).append(col)
    return {name: np.concatenate(cols) for name, cols in parts.items()}


@dataclass
class RawMessage:
    """One message as recorded: CDR bytes plus channel; ``decode()`` gives nested dicts."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    channel: ChannelInfo
    bag: Bag = field(repr=False)

    def decode(self) -> dict[str, Any]:
        defs = self.bag.definitions(self.channel)
        if defs is None:
            raise MessageDefinitionError(self.type, f"no definition for topic {self.topic}")
        return decode_cdr(self.data, defs, self.type)


def iter_messages(
    bag: Bag | str | os.PathLike[str],
    topics: Collection[str] | None = None,
    types: Collection[str] | None = None,
) -> Iterator[RawMessage]:
    """Every message (optionally only ``topics`` / ``types``), in file order within each chunk."""
    bag = _as_bag(bag)
    topic_set = None if topics is None else set(topics)
    type_set = None if types is None else {normalize_type(t) for t in types}

    def want(channel: ChannelInfo) -> bool:
        return (topic_set is None or channel.topic in topic_set) and (
            type_set is None or channel.type in type_set
        )

    for scan in bag.scans():
        for chunk in scan.chunks(want):
            for cid, log, pub, data in chunk.messages():
                channel = scan.channels[cid]
                yield RawMessage(channel.topic, channel.type, log, pub, data, channel, bag)


def data_lost(problems: Sequence[BagProblem], files: Sequence[Path]) -> list[BagProblem]:
    """The ``problems`` that mean recorded messages could not be read (``DATA_LOSS_KINDS``), and
    a file cut short that is not the last of ``files`` (a killed recorder cuts only its last)."""
    last = files[-1] if files else None
    return [
        p
        for p in problems
        if p.kind in DATA_LOSS_KINDS or (p.kind == "cut_short" and p.file != last)
    ]


@dataclass
class TopicInfo:
    name: str
    type: str
    message_count: int
    first_ns: int | None
    last_ns: int | None


@dataclass(frozen=True)
class Checks:
    """What a pass over the bag read and checked (``feeder info`` prints it)."""

    files: int
    chunks: int  # chunk records met
    decompressed: int  # chunks decompressed (every chunk with ``verify``)
    crc_checked: int  # chunks whose CRC-32 was compared
    frame_checked: int  # zstd chunks whose frame checksum zstd verified
    located: int  # message records located in decompressed chunks, checked against the indexes
    verified: bool = False  # every chunk decompressed and every message decoded
    decoded: int = 0  # messages CDR-decoded field by field (``verify``)
    undecodable: int = 0  # messages not decoded: no definition of their type, or not CDR

    @classmethod
    def of(cls, tallies: Sequence[ScanTally], verified: bool, decoded: int, skipped: int) -> Checks:
        return cls(
            files=len(tallies),
            chunks=sum(t.chunks for t in tallies),
            decompressed=sum(t.decompressed for t in tallies),
            crc_checked=sum(t.crc_checked for t in tallies),
            frame_checked=sum(t.frame_checked for t in tallies),
            located=sum(t.located for t in tallies),
            verified=verified,
            decoded=decoded,
            undecodable=skipped,
        )


@dataclass
class BagInfo:
    """What a bag holds, counted from its data (not from metadata.yaml, which a killed writer leaves
    stale): topics, message counts, time range, files, the problems found, and how many recorded
    messages are lost (``loss``: metadata.yaml's and the summaries' counts against the data)."""

    path: Path
    files: list[Path]
    topics: dict[str, TopicInfo]
    message_count: int
    start_ns: int | None
    end_ns: int | None
    cut_short: bool
    problems: list[BagProblem]
    metadata: dict[str, Any] | None
    loss: LossCount | None = None
    checks: Checks | None = None

    @property
    def duration_ns(self) -> int:
        return 0 if self.start_ns is None or self.end_ns is None else self.end_ns - self.start_ns

    def types(self) -> dict[str, str]:
        return {t.name: t.type for t in self.topics.values()}

    def lost_data(self) -> list[BagProblem]:
        """The problems that lost recorded messages (see :func:`data_lost`)."""
        return data_lost(self.problems, self.files)


def _count_chunk(topics: dict[str, TopicInfo], scan: FileScan, chunk: ChunkData) -> None:
    for cid, times in chunk.log_times.items():
        channel = scan.channels[cid]
        info = topics.get(channel.topic)
        if info is None:
            info = TopicInfo(channel.topic, channel.type, 0, None, None)
            topics[channel.topic] = info
        if len(times) == 0:
            continue
        info.message_count += len(times)
        lo, hi = int(times.min()), int(times.max())
        info.first_ns = lo if info.first_ns is None else min(info.first_ns, lo)
        info.last_ns = hi if info.last_ns is None else max(info.last_ns, hi)


def _decode_chunk(bag: Bag, scan: FileScan, chunk: ChunkData) -> tuple[int, int]:
    """Decode every message of a decompressed chunk field by field (``verify``): messages that
    end before their last field are reported as ``malformed_message``. Returns (decoded, not
    decoded: no definition of the type, or not CDR)."""
    decoded = skipped = 0
    for cid, records in chunk.records.items():
        channel = scan.channels[cid]
        if channel.message_encoding != "cdr":
            skipped += len(records)
            continue
        try:
            plan = bag.plan(channel)
        except UnsupportedLayoutError:  # no column layout: decode message by message
            decoded += _decode_each(bag, chunk, channel)
            continue
        if plan is None:
            skipped += len(records)
            continue
        for batch in _decode_batch(bag, chunk, channel, plan, plan.select(None)):
            decoded += len(batch)
    return decoded, skipped


def _decode_each(bag: Bag, chunk: ChunkData, channel: ChannelInfo) -> int:
    defs = bag.definitions(channel)
    if defs is None:
        return 0
    decoded = bad = 0
    for cid, _, _, data in chunk.messages():
        if cid != channel.id:
            continue
        try:
            decode_cdr(data, defs, channel.type)
            decoded += 1
        except (BagError, ValueError, IndexError, KeyError, UnicodeDecodeError):
            bad += 1
    if bad:
        bag.report(
            BagProblem(
                "malformed_message",
                chunk.file,
                f"{bad} {channel.type} message(s) cannot be decoded",
                chunk.offset,
                channel.topic,
            )
        )
    return decoded


def bag_info(bag: Bag | str | os.PathLike[str], *, verify: bool = False) -> BagInfo:
    """Count messages per topic and the time range by scanning the message indexes (and walking
    chunks without indexes), and how many recorded messages are lost. ``verify=True`` also
    decompresses and CRC-checks every chunk, checks every message record against its index and
    decodes every message whose type is known (a malformed one is reported)."""
    bag = _as_bag(bag)
    topics: dict[str, TopicInfo] = {}
    decoded = skipped = 0
    for scan in bag.scans():
        for chunk in scan.chunks(lambda _c: True, decode=verify):
            _count_chunk(topics, scan, chunk)
            if verify:
                done, left = _decode_chunk(bag, scan, chunk)
                decoded, skipped = decoded + done, skipped + left
        for channel in scan.channels.values():
            topics.setdefault(channel.topic, TopicInfo(channel.topic, channel.type, 0, None, None))
    firsts = [t.first_ns for t in topics.values() if t.first_ns is not None]
    lasts = [t.last_ns for t in topics.values() if t.last_ns is not None]
    return BagInfo(
        path=bag.path,
        files=list(bag.files),
        topics=topics,
        message_count=sum(t.message_count for t in topics.values()),
        start_ns=min(firsts) if firsts else None,
        end_ns=max(lasts) if lasts else None,
        cut_short=bag.cut_short,
        problems=list(bag.problems),
        metadata=bag.metadata,
        loss=bag.loss,
        checks=Checks.of(bag.tallies, verify, decoded, skipped),
    )
