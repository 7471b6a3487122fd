"""Sequential, chunk-by-chunk scan of one MCAP file, tolerant of truncation and corruption.

The scan reads records in file order and never holds more than one chunk (plus its message indexes).
Message records inside a chunk are located with the chunk's message indexes (read with numpy,
checked against the chunk buffer); a chunk without usable indexes (the last chunk of a killed
writer, other writers) is walked record by record. Schema and Channel records are picked up wherever
they are (data section or inside chunks). Problems are reported through a callback and the scan
carries on where the data allows: a corrupt chunk is skipped; a file that ends without a footer is
read up to its last complete chunk and flagged ``cut_short``.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lz4.frame  # type: ignore[import-untyped]
import numpy as np
import numpy.typing as npt
import zstandard

from feeder_ros.bag.errors import BagProblem
from feeder_ros.bag.mcap_format import MAGIC, Op
from feeder_ros.bag.msgdef import normalize_type

__all__ = ["ChannelInfo", "ChunkData", "FileScan", "ScanTally"]

IntArray = npt.NDArray[np.int64]
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_RECORD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQI")
_LOOSE_LIMIT = 4 << 20
_MAX_CHUNK = 1 << 31  # larger uncompressed chunks are taken for corruption, not allocated
_CUT_READ = 256 << 20  # of a chunk the file's end cut off, at most this much is read to count
_CUT_PIECE = 1024  # compressed bytes fed at a time when counting it (bounds the output kept)
_KNOWN_OPS = frozenset(range(0x01, 0x10))


@dataclass(frozen=True)
class ChannelInfo:
    """An MCAP channel with its schema: ``type`` is ``pkg/msg/Type`` ("" without a schema)."""

    id: int
    topic: str
    type: str
    message_encoding: str
    schema_encoding: str
    schema_text: str
    metadata: dict[str, str] = field(default_factory=dict)


@dataclass
class ScanTally:
    """What one pass over a file met, per channel id: the messages it located (readable) and the
    messages of chunks it had to skip or that the file's end cut off (lost, as far as their message
    indexes or the readable part of a cut chunk tell), and what was checked (``feeder info``)."""

    chunks: int = 0  # chunk records met
    decompressed: int = 0  # of those, decompressed (all with --verify; otherwise where needed)
    crc_checked: int = 0  # decompressed chunks whose CRC-32 was compared
    frame_checked: int = 0  # zstd chunks whose frame checksum zstd verified while decompressing
    located: int = 0  # message records located in decompressed chunks (checked against the index)
    readable: dict[int, int] = field(default_factory=dict)
    lost: dict[int, int] = field(default_factory=dict)
    #: chunks skipped or cut off whose message count nothing tells (no usable message index)
    uncounted_chunks: int = 0

    @staticmethod
    def count(counts: dict[int, int], cid: int, n: int) -> None:
        """Add ``n`` messages of channel ``cid`` (-1: a channel that cannot be told)."""
        counts[cid] = counts.get(cid, 0) + n


@dataclass
class ChunkData:
    """Messages of the wanted channels in one chunk, per channel id and in file order: offsets of
    the message records in ``buf``, where each record ends, log and publish times. Only counting
    (``decode=False``): ``buf`` is None and only ``records`` and ``log_times`` are filled."""

    file: Path
    offset: int  # byte offset of the chunk record in the file
    buf: npt.NDArray[np.uint8] | None  # uncompressed records
    records: dict[int, IntArray]
    log_times: dict[int, IntArray]
    ends: dict[int, IntArray] = field(default_factory=dict)
    publish_times: dict[int, IntArray] = field(default_factory=dict)

    def data_bounds(self, cid: int) -> tuple[IntArray, IntArray]:
        """Start and end in ``buf`` of the message data (CDR) of channel ``cid``."""
        return self.records[cid] + 31, self.ends[cid]

    def messages(self) -> Iterator[tuple[int, int, int, bytes]]:
        """``(channel id, log time, publish time, data)`` of every message, in file order."""
        assert self.buf is not None
        raw = self.buf.data
        cids = list(self.records)
        offs = np.concatenate([self.records[c] for c in cids])
        which = np.concatenate([np.full(len(self.records[c]), c) for c in cids]).tolist()
        starts = (offs + 31).tolist()
        ends = np.concatenate([self.ends[c] for c in cids]).tolist()
        logs = np.concatenate([self.log_times[c] for c in cids]).tolist()
        pubs = np.concatenate([self.publish_times[c] for c in cids]).tolist()
        for i in np.argsort(offs, kind="stable").tolist():
            yield which[i], logs[i], pubs[i], bytes(raw[starts[i] : ends[i]])


# The fixed part of a Message record: opcode, length, channel, sequence, log and publish time.
_MESSAGE_HEAD = np.dtype(
    {
        "names": ["op", "length", "channel", "log", "publish"],
        "formats": ["u1", "<u8", "<u2", "<u8", "<u8"],
        "offsets": [0, 1, 9, 15, 23],
        "itemsize": 31,
    }
)


def _read_str(data: bytes | memoryview, pos: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(data, pos)
    end = pos + 4 + n
    if end > len(data):
        raise ValueError(f"string of {n} bytes runs past the record end")
    return bytes(data[pos + 4 : end]).decode("utf-8"), end


def _read_map(data: bytes | memoryview, pos: int) -> tuple[dict[str, str], int]:
    (n,) = _U32.unpack_from(data, pos)
    end = pos + 4 + n
    out: dict[str, str] = {}
    pos += 4
    while pos < end:
        key, pos = _read_str(data, pos)
        out[key], pos = _read_str(data, pos)
    return out, end


def _gather_u64(buf: npt.NDArray[np.uint8], at: IntArray) -> IntArray:
    view = np.ndarray((len(buf) - 7,), dtype="<u8", buffer=buf, strides=(1,))
    return view[at].astype(np.int64)


@dataclass
class _PendingChunk:
    offset: int
    body: bytes
    indexes: dict[int, bytes] = field(default_factory=dict)


class FileScan:
    """One MCAP file, read in order. Iterate ``chunks(want)``; then ``complete`` says if the footer
    was reached, and ``schemas``/``channels``/``metadata`` hold what was found."""

    def __init__(
        self, path: Path, report: Callable[[BagProblem], None], verify_crc: bool = True
    ) -> None:
        self.path = path
        self.report = report
        self.verify_crc = verify_crc
        self.schemas: dict[int, tuple[str, str, str]] = {}  # id -> (name, encoding, text)
        self.channels: dict[int, ChannelInfo] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.complete = False
        self.statistics: dict[str, Any] | None = None
        self.tally = ScanTally()
        self._pending_channels: dict[int, tuple[int, str, str, dict[str, str]]] = {}

    # ------------------------------------------------------------------ records

    def _problem(
        self,
        kind: str,
        detail: str,
        offset: int | None = None,
        topic: str | None = None,
        lost_ns: int | None = None,
    ) -> None:
        self.report(BagProblem(kind, self.path, detail, offset, topic, lost_ns))

    def _schema(self, body: bytes | memoryview) -> None:
        (sid,) = _U16.unpack_from(body, 0)
        name, pos = _read_str(body, 2)
        encoding, pos = _read_str(body, pos)
        (n,) = _U32.unpack_from(body, pos)
        text = bytes(body[pos + 4 : pos + 4 + n]).decode("utf-8", "replace")
        self.schemas[sid] = (name, encoding, text)
        for cid, pending in list(self._pending_channels.items()):
            if pending[0] == sid:
                del self._pending_channels[cid]
                self._add_channel(cid, *pending)

    def _channel(self, body: bytes | memoryview) -> None:
        cid, sid = struct.unpack_from("<HH", body, 0)
        topic, pos = _read_str(body, 4)
        encoding, pos = _read_str(body, pos)
        meta, _ = _read_map(body, pos)
        if sid != 0 and sid not in self.schemas:
            self._pending_channels[cid] = (sid, topic, encoding, meta)
        self._add_channel(cid, sid, topic, encoding, meta)

    def _add_channel(
        self, cid: int, sid: int, topic: str, encoding: str, meta: dict[str, str]
    ) -> None:
        name, schema_encoding, text = self.schemas.get(sid, ("", "", ""))
        try:
            type_name = normalize_type(name) if name else ""
        except ValueError:
            type_name = name
        self.channels[cid] = ChannelInfo(
            cid, topic, type_name, encoding, schema_encoding, text, meta
        )

    def _metadata_record(self, body: bytes) -> None:
        name, pos = _read_str(body, 0)
        self.metadata[name], _ = _read_map(body, pos)

    def _statistics(self, body: bytes) -> None:
        count, _, _, _, _, chunks, start, end = struct.unpack_from("<QHIIIIQQ", body, 0)
        self.statistics = {
            "message_count": count,
            "chunk_count": chunks,
            "start": start,
            "end": end,
            "channel_message_counts": _channel_counts(body),
        }

    # ------------------------------------------------------------------ scan

    def chunks(
        self, want: Callable[[ChannelInfo], bool], decode: bool = True
    ) -> Iterator[ChunkData]:
        """Yield the wanted channels' messages chunk by chunk (``decode=False``: counts and times
        from the message indexes only, without decompressing indexed chunks)."""
        try:
            f = open(self.path, "rb")  # noqa: SIM115 - closed in finally
        except OSError as err:
            self._problem("unreadable", f"cannot open: {err}")
            return
        try:
            yield from self._scan(f, want, decode)
        finally:
            f.close()

    def _scan(
        self, f: Any, want: Callable[[ChannelInfo], bool], decode: bool
    ) -> Iterator[ChunkData]:
        size = os.fstat(f.fileno()).st_size
        if f.read(8) != MAGIC:
            self._problem("not_mcap", "the file does not start with the MCAP magic", 0)
            return
        # a complete file's summary lists every schema and channel: with them known from the
        # start, a chunk of unwanted topics is skipped on its indexes even when it is the chunk
        # that holds the channel records (mcap's writer puts them in the first chunk they need)
        self._resync(f, size, 0)
        pending: _PendingChunk | None = None
        loose = bytearray()
        loose_offset = 0
        while True:
            pos = f.tell()
            head = f.read(9)
            if len(head) < 9:
                if pending is not None:  # its message indexes may be incomplete: walk the chunk
                    yield from self._chunk(pending, want, decode, trust_index=False)
                    pending = None
                yield from self._loose(loose, loose_offset, want)
                self._problem(
                    "cut_short",
                    f"the file ends at byte {size} without a footer (the writer was killed?); "
                    "read up to the last complete chunk",
                    pos,
                )
                if head:
                    self._cut_record(head[0], pos, b"", size)
                return
            op, length = _RECORD.unpack(head)
            if op not in _KNOWN_OPS or length > size - pos - 9:
                if pending is not None:
                    yield from self._chunk(pending, want, decode, trust_index=False)
                    pending = None
                yield from self._loose(loose, loose_offset, want)
                loose = bytearray()
                resume = self._resync(f, size, pos)
                what = (
                    f"unknown opcode 0x{op:02x}"
                    if op not in _KNOWN_OPS
                    else f"record 0x{op:02x} needs {length} bytes but the file ends after "
                    f"{size - pos - 9}"
                )
                if resume is not None:
                    self._problem(
                        "corrupt_record",
                        f"{what}; bytes {pos}..{resume} skipped, resuming at the next chunk "
                        "listed in the summary",
                        pos,
                    )
                    f.seek(resume)
                    continue
                kind = (
                    "corrupt_record"
                    if op not in _KNOWN_OPS or self._has_footer(f, size)
                    else "cut_short"
                )
                self._problem(kind, f"{what}; read up to the last complete chunk", pos)
                if kind == "cut_short":
                    f.seek(pos + 9)
                    self._cut_record(op, pos, f.read(_CUT_READ), size)
                return
            if op == Op.MESSAGE_INDEX and pending is not None:
                body = f.read(length)
                (cid,) = _U16.unpack_from(body, 0)
                pending.indexes[cid] = body
                continue
            if pending is not None:
                yield from self._chunk(pending, want, decode, trust_index=True)
                pending = None
            if op == Op.MESSAGE:
                if not loose:
                    loose_offset = pos
                loose += head + f.read(length)
                if len(loose) >= _LOOSE_LIMIT:
                    yield from self._loose(loose, loose_offset, want)
                    loose = bytearray()
                continue
            if loose:
                yield from self._loose(loose, loose_offset, want)
                loose = bytearray()
            if op == Op.CHUNK:
                pending = _PendingChunk(pos, f.read(length))
            elif op == Op.FOOTER:
                f.seek(length, 1)
                if f.read(8) != MAGIC:
                    self._problem("corrupt_record", "no MCAP magic after the footer", f.tell())
                self.complete = True
                return
            elif op in (Op.SCHEMA, Op.CHANNEL, Op.METADATA, Op.STATISTICS):
                body = f.read(length)
                try:
                    if op == Op.SCHEMA:
                        self._schema(body)
                    elif op == Op.CHANNEL:
                        self._channel(body)
                    elif op == Op.METADATA:
                        self._metadata_record(body)
                    else:
                        self._statistics(body)
                except (ValueError, struct.error) as err:
                    self._problem("corrupt_record", f"cannot parse record 0x{op:02x}: {err}", pos)
            else:
                f.seek(length, 1)

    @staticmethod
    def _has_footer(f: Any, size: int) -> bool:
        if size < 8 + 29 + 8:
            return False
        f.seek(size - 8)
        return bool(f.read(8) == MAGIC)

    def _resync(self, f: Any, size: int, pos: int) -> int | None:
        """Offset of the first chunk after ``pos`` from the summary's chunk indexes, if the file
        has an intact footer and summary; Schema/Channel records of the summary are taken too."""
        here = f.tell()
        try:
            if not self._has_footer(f, size):
                return None
            f.seek(size - 8 - 29)
            op, length, summary_start, _, _ = struct.unpack("<BQQQI", f.read(29))
            if op != Op.FOOTER or length != 20 or not 8 <= summary_start < size - 37:
                return None
            f.seek(summary_start)
            data = f.read(size - 37 - summary_start)
            offsets: list[int] = []
            at = 0
            while at + 9 <= len(data):
                rop, rlen = _RECORD.unpack_from(data, at)
                body = memoryview(data)[at + 9 : at + 9 + rlen]
                if rop == Op.CHUNK_INDEX:
                    offsets.append(_U64.unpack_from(body, 16)[0])
                elif rop in (Op.SCHEMA, Op.CHANNEL):
                    self._inner_record(rop, body, summary_start + at)
                at += 9 + rlen
            later = [o for o in offsets if o > pos]
            return min(later) if later else None
        except (struct.error, ValueError):
            return None
        finally:
            f.seek(here)

    def _loose(
        self, loose: bytearray, offset: int, want: Callable[[ChannelInfo], bool]
    ) -> Iterator[ChunkData]:
        if loose:
            buf = np.frombuffer(bytes(loose), np.uint8)
            yield from self._walk(buf, offset, want)

    def _chunk(
        self,
        chunk: _PendingChunk,
        want: Callable[[ChannelInfo], bool],
        decode: bool,
        trust_index: bool,
    ) -> Iterator[ChunkData]:
        body = chunk.body
        self.tally.chunks += 1
        try:
            start, end, usize, crc = _CHUNK_HEAD.unpack_from(body, 0)
            compression, pos = _read_str(body, 28)
            (clen,) = _U64.unpack_from(body, pos)
            data = memoryview(body)[pos + 8 : pos + 8 + clen]
            if len(data) != clen:
                raise ValueError(f"compressed data of {clen} bytes runs past the record")
        except (ValueError, struct.error) as err:
            self._problem(
                "corrupt_chunk",
                f"cannot parse the chunk header ({err}); chunk skipped",
                chunk.offset,
            )
            self._count_skipped(chunk)
            return
        lost = max(end - start, 0)  # the recording time a skip of this chunk loses
        index = self._parse_indexes(chunk) if trust_index and chunk.indexes else None
        if index is not None:
            known = all(cid in self.channels for cid in index)
            wanted = [cid for cid in index if cid in self.channels and want(self.channels[cid])]
            if known and (not wanted or not decode):  # counted from the message indexes
                for cid, (stamps, _) in index.items():
                    self.tally.count(self.tally.readable, cid, len(stamps))
            if known and not wanted:
                return
            if not decode and known:
                recs = {cid: index[cid][1] for cid in wanted}
                times = {cid: index[cid][0] for cid in wanted}
                yield ChunkData(self.path, chunk.offset, None, recs, times)
                return
        if usize > _MAX_CHUNK:
            self._problem(
                "corrupt_chunk",
                f"implausible uncompressed size {usize} bytes; chunk skipped",
                chunk.offset,
                lost_ns=lost,
            )
            self._count_skipped(chunk)
            return
        checksummed = False  # zstd verifies its own frame checksum (XXH64) while decompressing
        try:
            if compression == "zstd":
                raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
                checksummed = zstandard.get_frame_parameters(data).has_checksum
            elif compression == "lz4":
                raw = lz4.frame.decompress(data)
            elif compression == "":
                raw = bytes(data)
            else:
                self._problem(
                    "corrupt_chunk",
                    f"unknown compression {compression!r}; chunk skipped",
                    chunk.offset,
                    lost_ns=lost,
                )
                self._count_skipped(chunk)
                return
        except Exception as err:  # zstd/lz4 raise their own error types
            self._problem(
                "corrupt_chunk",
                f"{compression} decompression failed ({err}); chunk skipped",
                chunk.offset,
                lost_ns=lost,
            )
            self._count_skipped(chunk)
            return
        if len(raw) != usize:
            self._problem(
                "corrupt_chunk",
                f"decompressed to {len(raw)} bytes, header says {usize}; chunk skipped",
                chunk.offset,
                lost_ns=lost,
            )
            self._count_skipped(chunk)
            return
        self.tally.decompressed += 1
        self.tally.frame_checked += checksummed
        if crc and self.verify_crc and not checksummed:
            self.tally.crc_checked += 1
            if zlib.crc32(raw) != crc:
                self._problem(
                    "corrupt_chunk",
                    "CRC mismatch of the uncompressed records; chunk skipped",
                    chunk.offset,
                    lost_ns=lost,
                )
                self._count_skipped(chunk)
                return
        buf = np.frombuffer(raw, np.uint8)
        if index is not None:
            yield from self._indexed(buf, chunk.offset, index, want)
        else:
            yield from self._walk(buf, chunk.offset, want)

    def _count_skipped(self, chunk: _PendingChunk) -> None:
        """The messages of a skipped chunk are lost: count them from its message indexes (the
        records after the chunk), or count the chunk as one whose messages nothing counts."""
        index = self._parse_indexes(chunk) if chunk.indexes else None
        if index is None:
            self.tally.uncounted_chunks += 1
            return
        for cid, (stamps, _) in index.items():
            self.tally.count(self.tally.lost, cid, len(stamps))

    def _cut_record(self, op: int, pos: int, body: bytes, size: int) -> None:
        """The file ends inside the record at ``pos`` (``body``: what there is of its content). A
        chunk or message cut off this way held messages that are lost: count those whose records
        are complete in the readable part of the chunk (a lower bound: the rest of it is gone)."""
        if op == Op.MESSAGE:
            cid = _U16.unpack_from(body, 0)[0] if len(body) >= 2 else -1
            self.tally.count(self.tally.lost, cid, 1)
            self._problem("cut_chunk", "the file ends inside a message record: 1 message lost", pos)
            return
        if op != Op.CHUNK:
            return
        counted, what, lost_ns = self._count_cut_chunk(body)
        self.tally.uncounted_chunks += 1  # what the missing part of the chunk held is not known
        for cid, n in counted.items():
            self.tally.count(self.tally.lost, cid, n)
        total = sum(counted.values())
        lost = f"at least {total} message(s) lost with it" if total else "its messages are lost"
        self._problem(
            "cut_chunk",
            f"the file ends inside a chunk ({size - pos} bytes of it present; {what}): {lost}",
            pos,
            lost_ns=lost_ns,
        )

    def _count_cut_chunk(self, body: bytes) -> tuple[dict[int, int], str, int | None]:
        """Messages per channel id whose records are complete in the readable part of a chunk cut
        off by the file's end; a description of that part; the time span of the chunk [ns]."""
        try:
            start, end, usize, _ = _CHUNK_HEAD.unpack_from(body, 0)
            compression, pos = _read_str(body, 28)
        except (ValueError, struct.error):
            return {}, "its header is incomplete", None
        raw = _decompress_prefix(compression, body[pos + 8 :], min(usize, _MAX_CHUNK))
        counted: dict[int, int] = {}
        at = 0
        while at + 9 <= len(raw):
            rop, length = _RECORD.unpack_from(raw, at)
            if at + 9 + length > len(raw):
                break
            if rop == Op.MESSAGE and length >= 2:
                cid = _U16.unpack_from(raw, at + 9)[0]
                counted[cid] = counted.get(cid, 0) + 1
            elif rop in (Op.SCHEMA, Op.CHANNEL):
                self._inner_record(rop, memoryview(raw)[at + 9 : at + 9 + length], 0)
            at += 9 + length
        what = f"{len(raw)} of its {usize} bytes of records could be decompressed"
        return counted, what, max(end - start, 0) or None

    def _parse_indexes(self, chunk: _PendingChunk) -> dict[int, tuple[IntArray, IntArray]] | None:
        out: dict[int, tuple[IntArray, IntArray]] = {}
        for cid, body in chunk.indexes.items():
            (n,) = _U32.unpack_from(body, 2)
            if n % 16 or 6 + n > len(body):
                return None
            pairs = np.frombuffer(body, "<u8", n // 8, 6).reshape(-1, 2).astype(np.int64)
            order = np.argsort(pairs[:, 1], kind="stable")
            out[cid] = (pairs[order, 0], pairs[order, 1])
        return out

    def _indexed(
        self,
        buf: npt.NDArray[np.uint8],
        offset: int,
        index: dict[int, tuple[IntArray, IntArray]],
        want: Callable[[ChannelInfo], bool],
    ) -> Iterator[ChunkData]:
        """Messages located by the message indexes, checked against the chunk with ONE gather of
        all record headers; records between them (schemas, channels) are walked; an index that
        does not fit the chunk is ignored and the chunk walked."""
        size = len(buf)
        present = sorted(cid for cid, (_, o) in index.items() if len(o))
        offs = np.concatenate([o for _, o in index.values()])
        cids = np.concatenate([np.full(len(o), cid, np.int64) for cid, (_, o) in index.items()])
        order = np.argsort(offs, kind="stable")
        offs, cids = offs[order], cids[order]
        if len(offs) and (offs[0] < 0 or offs[-1] + 31 > size):
            yield from self._walk(buf, offset, want)
            return
        heads = _headers(buf, offs)
        ends = offs + 9 + heads["length"].astype(np.int64)
        fits = (
            np.all(heads["op"] == Op.MESSAGE)
            and np.all(heads["channel"] == cids)
            and np.all(heads["length"] >= 22)
            and np.all(ends[:-1] <= offs[1:])
            and (len(ends) == 0 or ends[-1] <= size)
        )
        if not fits:
            yield from self._walk(buf, offset, want)
            return
        gap_starts = np.concatenate(([0], ends))
        gap_ends = np.concatenate((offs, [size]))
        gaps = gap_starts < gap_ends
        for gs, ge in zip(gap_starts[gaps].tolist(), gap_ends[gaps].tolist(), strict=True):
            if not self._walk_meta(buf, gs, ge, offset):
                yield from self._walk(buf, offset, want)
                return
        yield from self._emit(buf, offset, offs, cids, heads, ends, want, present)

    def _emit(
        self,
        buf: npt.NDArray[np.uint8],
        offset: int,
        offs: IntArray,
        cids: IntArray,
        heads: npt.NDArray[Any],
        ends: IntArray,
        want: Callable[[ChannelInfo], bool],
        present: list[int],
    ) -> Iterator[ChunkData]:
        chunk = ChunkData(self.path, offset, buf, {}, {})
        single = len(present) == 1
        self.tally.located += len(offs)
        for cid in present:
            channel = self.channels.get(cid)
            counts = self.tally.readable if channel is not None else self.tally.lost
            self.tally.count(
                counts, cid, len(offs) if single else int(np.count_nonzero(cids == cid))
            )
            if channel is None:
                self._problem(
                    "unknown_channel", f"messages of channel {cid}, which was never defined", offset
                )
                continue
            if not want(channel):
                continue
            sel: slice | IntArray = slice(None) if single else np.flatnonzero(cids == cid)
            chunk.records[cid] = offs[sel]
            chunk.ends[cid] = ends[sel]
            chunk.log_times[cid] = heads["log"][sel].astype(np.int64)
            chunk.publish_times[cid] = heads["publish"][sel].astype(np.int64)
        if chunk.records:
            yield chunk

    def _walk_meta(self, buf: npt.NDArray[np.uint8], start: int, end: int, offset: int) -> bool:
        raw = buf.data
        pos = start
        while pos < end:
            if pos + 9 > end:
                return False
            op, length = _RECORD.unpack_from(raw, pos)
            if pos + 9 + length > end or op == Op.MESSAGE:
                return False
            self._inner_record(op, raw[pos + 9 : pos + 9 + length], offset)
            pos += 9 + length
        return True

    def _inner_record(self, op: int, body: memoryview, offset: int) -> None:
        try:
            if op == Op.SCHEMA:
                self._schema(body)
            elif op == Op.CHANNEL:
                self._channel(body)
        except (ValueError, struct.error) as err:
            self._problem(
                "corrupt_record", f"cannot parse record 0x{op:02x} in a chunk: {err}", offset
            )

    def _walk(
        self, buf: npt.NDArray[np.uint8], offset: int, want: Callable[[ChannelInfo], bool]
    ) -> Iterator[ChunkData]:
        """Locate the records of a chunk without indexes, one record at a time (slow path)."""
        raw = buf.data
        size = len(buf)
        found: dict[int, list[int]] = {}
        pos = 0
        unpack = _RECORD.unpack_from
        u16 = _U16.unpack_from
        while pos + 9 <= size:
            op, length = unpack(raw, pos)
            if pos + 9 + length > size:
                self._problem(
                    "corrupt_chunk",
                    f"a record at byte {pos} of the chunk runs past its end; the rest of the "
                    "chunk skipped",
                    offset,
                )
                self.tally.uncounted_chunks += 1
                break
            if op == Op.MESSAGE:
                if length < 22:
                    self._problem(
                        "corrupt_chunk", f"a message record at byte {pos} is too short", offset
                    )
                    cid = u16(raw, pos + 9)[0] if length >= 2 else -1
                    self.tally.count(self.tally.lost, cid, 1)
                else:
                    found.setdefault(u16(raw, pos + 9)[0], []).append(pos)
            else:
                self._inner_record(op, raw[pos + 9 : pos + 9 + length], offset)
            pos += 9 + length
        if not found:
            return
        offs = np.concatenate([np.asarray(p, np.int64) for p in found.values()])
        cids = np.concatenate([np.full(len(p), cid, np.int64) for cid, p in found.items()])
        order = np.argsort(offs, kind="stable")
        offs, cids = offs[order], cids[order]
        heads = _headers(buf, offs)
        ends = offs + 9 + heads["length"].astype(np.int64)
        yield from self._emit(buf, offset, offs, cids, heads, ends, want, sorted(found))


def _decompress_prefix(compression: str, data: bytes, limit: int) -> bytes:
    """What can be decompressed of the start of a chunk's data (at most ``limit`` bytes; fed in
    small pieces so that a damaged frame cannot expand far past it); b"" when nothing can."""
    out = bytearray()
    try:
        if compression == "zstd":
            stream = zstandard.ZstdDecompressor().decompressobj()
            for at in range(0, len(data), _CUT_PIECE):
                out += stream.decompress(data[at : at + _CUT_PIECE])
                if len(out) >= limit:
                    break
        elif compression == "lz4":
            out += lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit)
        elif compression == "":
            out += data[:limit]
    except Exception:  # zstd/lz4 raise their own error types: what came out before counts
        pass
    return bytes(out[:limit])


def _channel_counts(body: bytes) -> dict[int, int] | None:
    """The per-channel message counts of a Statistics record (None: absent or malformed; the
    total still counts)."""
    if len(body) < 46:
        return None
    (size,) = _U32.unpack_from(body, 42)
    if size % 10 or 46 + size > len(body):
        return None
    counts: dict[int, int] = {}
    for at in range(46, 46 + size, 10):
        cid, n = struct.unpack_from("<HQ", body, at)
        counts[cid] = n
    return counts


def _headers(buf: npt.NDArray[np.uint8], offs: IntArray) -> npt.NDArray[Any]:
    """The fixed part of the Message records at ``offs`` (each must have 31 bytes in ``buf``)."""
    if len(buf) < 31:
        return np.zeros(0, _MESSAGE_HEAD)
    view = np.ndarray((len(buf) - 30,), dtype=_MESSAGE_HEAD, buffer=buf, strides=(1,))
    return view[offs]
