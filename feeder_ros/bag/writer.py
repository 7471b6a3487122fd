"""``BagWriter``: record serialized ROS 2 messages into a rosbag2 bag (MCAP storage), without ROS.

The bag is a directory ``<name>/`` with ``metadata.yaml`` (rosbag2 ``version: 9``) and the MCAP
files ``<name>_0.mcap``, ``<name>_1.mcap``, ... (profile ``ros2``, ``ros2msg`` schemas with every
dependent definition, ``cdr`` messages, channel metadata ``offered_qos_profiles``). Messages are
collected in chunks (zstd, lz4 or uncompressed), each followed by its message indexes; the summary,
the ``rosbag2`` metadata record and the footer are written when a file is closed.

Crash safety: every finished chunk is written with its indexes in one ``write`` and flushed to the
operating system, and ``metadata.yaml`` is written when the bag starts and rewritten (temp file +
rename) on each split and on ``close``. A writer killed with SIGKILL leaves every complete chunk on
disk; the reader reports the last file as cut short and reads it up to its last complete chunk.
Chunks are not fsynced: data in the page cache survives a killed process, not a power cut.
"""

from __future__ import annotations

import os
import struct
import zlib
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO

import lz4.frame  # type: ignore[import-untyped]
import numpy as np
import yaml
import zstandard

from feeder_ros.bag.errors import WriterStateError
from feeder_ros.bag.mcap_format import (
    MAGIC,
    MESSAGE_FIXED,
    MESSAGE_HEADER,
    Op,
    encode_map,
    encode_record,
    encode_str,
    encode_u16_u64_map,
)
from feeder_ros.bag.msgdef import normalize_type
from feeder_ros.bag.schemas import ros2msg_schema, type_description_hash
from feeder_ros.ros_compat import ros_distro as ros_distro_in_use

__all__ = ["COMPRESSIONS", "METADATA_VERSION", "BagWriter", "default_qos_yaml"]

METADATA_VERSION = 9
COMPRESSIONS = ("zstd", "lz4", "none")
LIBRARY = "feeder_ros.bag"
_INFINITE = {
    "sec": 9223372036,
    "nsec": 854775807,
}  # rmw's "infinite" duration, as rosbag2 writes it


def default_qos_yaml(
    reliability: str = "reliable", durability: str = "volatile", depth: int = 10
) -> str:
    """One offered QoS profile as the YAML string rosbag2 stores (keep_last, no deadline)."""
    profile = {
        "history": "keep_last",
        "depth": depth,
        "reliability": reliability,
        "durability": durability,
        "deadline": dict(_INFINITE),
        "lifespan": dict(_INFINITE),
        "liveliness": "automatic",
        "liveliness_lease_duration": dict(_INFINITE),
        "avoid_ros_namespace_conventions": False,
    }
    return str(yaml.safe_dump([profile], sort_keys=False))


@dataclass
class _Topic:
    name: str
    type: str
    qos_yaml: str
    schema_text: str
    type_hash: str
    count: int = 0


@dataclass
class _FileStats:
    path: Path
    start: int | None = None
    end: int | None = None
    count: int = 0


@dataclass
class _Channel:
    id: int
    topic: _Topic
    index: array[int] = field(default_factory=lambda: array("Q"))  # (log_time, offset) pairs
    count: int = 0  # messages in the current file
    sequence: int = 0


class _McapFile:
    """One MCAP file being written: data section, chunks, indexes, summary."""

    def __init__(self, path: Path, compression: str, level: int) -> None:
        self.path = path
        self.compression = compression
        self._zstd = (  # with a frame checksum, which readers verify far faster than the CRC
            zstandard.ZstdCompressor(level=level, write_checksum=True)
            if compression == "zstd"
            else None
        )
        self.stream: BinaryIO = open(path, "xb")  # noqa: SIM115 - closed in close()
        self.offset = 0
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, _Channel] = {}  # by topic name (the latest channel of a name)
        #: every channel (reindex copies a file where one name may have channels of two types)
        self.all_channels: list[_Channel] = []
        self.schema_records: list[bytes] = []
        self.channel_records: list[bytes] = []
        self.chunk_indexes: list[bytes] = []
        self.metadata_indexes: list[bytes] = []
        self.chunk = bytearray()
        self.chunk_start = 0
        self.chunk_end = 0
        self.chunk_count = 0
        self.message_count = 0
        self.start_time: int | None = None
        self.end_time = 0
        self._write(MAGIC + encode_record(Op.HEADER, encode_str("ros2") + encode_str(LIBRARY)))

    def _write(self, data: bytes) -> None:
        self.stream.write(data)
        self.offset += len(data)

    def add_channel(self, topic: _Topic) -> _Channel:
        schema_id = self.schemas.get(topic.type)
        out = b""
        if schema_id is None:
            schema_id = len(self.schemas) + 1
            self.schemas[topic.type] = schema_id
            body = struct.pack("<H", schema_id) + encode_str(topic.type) + encode_str("ros2msg")
            raw = topic.schema_text.encode("utf-8")
            record = encode_record(Op.SCHEMA, body + struct.pack("<I", len(raw)) + raw)
            self.schema_records.append(record)
            out += record
        channel = _Channel(len(self.all_channels) + 1, topic)
        self.channels[topic.name] = channel
        self.all_channels.append(channel)
        metadata = {"offered_qos_profiles": topic.qos_yaml, "topic_type_hash": topic.type_hash}
        body = struct.pack("<HH", channel.id, schema_id) + encode_str(topic.name)
        record = encode_record(Op.CHANNEL, body + encode_str("cdr") + encode_map(metadata))
        self.channel_records.append(record)
        self._write(out + record)
        self.stream.flush()
        return channel

    def add_message(self, channel: _Channel, data: bytes, log_time: int, publish_time: int) -> None:
        chunk = self.chunk
        if not chunk:
            self.chunk_start = log_time
            self.chunk_end = log_time
        elif log_time < self.chunk_start:
            self.chunk_start = log_time
        if log_time > self.chunk_end:
            self.chunk_end = log_time
        channel.index.append(log_time)
        channel.index.append(len(chunk))
        chunk += MESSAGE_HEADER.pack(
            Op.MESSAGE,
            MESSAGE_FIXED + len(data),
            channel.id,
            channel.sequence,
            log_time,
            publish_time,
        )
        chunk += data
        channel.sequence = (channel.sequence + 1) & 0xFFFFFFFF
        channel.count += 1
        self.message_count += 1
        if self.start_time is None or log_time < self.start_time:
            self.start_time = log_time
        if log_time > self.end_time:
            self.end_time = log_time

    def finish_chunk(self) -> None:
        """Write the open chunk and its message indexes in one write, then flush."""
        if not self.chunk:
            return
        raw = bytes(self.chunk)
        if self._zstd is not None:
            packed = self._zstd.compress(raw)
        elif self.compression == "lz4":
            packed = lz4.frame.compress(raw)
        else:
            packed = raw
        name = "" if self.compression == "none" else self.compression
        head = struct.pack("<QQQI", self.chunk_start, self.chunk_end, len(raw), zlib.crc32(raw))
        chunk_record = encode_record(
            Op.CHUNK, head + encode_str(name) + struct.pack("<Q", len(packed)) + packed
        )
        chunk_offset = self.offset
        index_offsets: dict[int, int] = {}
        pos = chunk_offset + len(chunk_record)
        parts = [chunk_record]
        for channel in self.all_channels:
            if not channel.index:
                continue
            pairs = np.frombuffer(channel.index, dtype="<u8").reshape(-1, 2)
            if np.any(np.diff(pairs[:, 0].astype(np.int64)) < 0):  # index sorted by log time
                pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
            entries = pairs.tobytes()
            record = encode_record(
                Op.MESSAGE_INDEX, struct.pack("<HI", channel.id, len(entries)) + entries
            )
            index_offsets[channel.id] = pos
            pos += len(record)
            parts.append(record)
            channel.index = array("Q")
        self._write(b"".join(parts))
        self.stream.flush()
        index_length = pos - chunk_offset - len(chunk_record)
        self.chunk_indexes.append(
            encode_record(
                Op.CHUNK_INDEX,
                struct.pack(
                    "<QQQQ", self.chunk_start, self.chunk_end, chunk_offset, len(chunk_record)
                )
                + encode_u16_u64_map(index_offsets)
                + struct.pack("<Q", index_length)
                + encode_str(name)
                + struct.pack("<QQ", len(packed), len(raw)),
            )
        )
        self.chunk_count += 1
        self.chunk = bytearray()

    def close(self, metadata_yaml: str, ros_distro: str) -> None:
        """Finish the data section (with the ``rosbag2`` metadata record), summary and footer."""
        self.finish_chunk()
        meta = encode_record(
            Op.METADATA,
            encode_str("rosbag2")
            + encode_map({"serialized_metadata": metadata_yaml, "ROS_DISTRO": ros_distro}),
        )
        self.metadata_indexes.append(
            encode_record(
                Op.METADATA_INDEX,
                struct.pack("<QQ", self.offset, len(meta)) + encode_str("rosbag2"),
            )
        )
        self._write(meta + encode_record(Op.DATA_END, struct.pack("<I", 0)))
        summary_start = self.offset
        counts = {c.id: c.count for c in self.all_channels}
        statistics = encode_record(
            Op.STATISTICS,
            struct.pack(
                "<QHIIIIQQ",
                self.message_count,
                len(self.schemas),
                len(self.all_channels),
                0,
                len(self.metadata_indexes),
                self.chunk_count,
                self.start_time or 0,
                self.end_time,
            )
            + encode_u16_u64_map(counts),
        )
        groups = [
            (Op.SCHEMA, self.schema_records),
            (Op.CHANNEL, self.channel_records),
            (Op.STATISTICS, [statistics]),
            (Op.CHUNK_INDEX, self.chunk_indexes),
            (Op.METADATA_INDEX, self.metadata_indexes),
        ]
        summary = bytearray()
        offsets = bytearray()
        for opcode, records in groups:
            if not records:
                continue
            group = b"".join(records)
            offsets += encode_record(
                Op.SUMMARY_OFFSET,
                struct.pack("<BQQ", opcode, summary_start + len(summary), len(group)),
            )
            summary += group
        summary_offset_start = summary_start + len(summary)
        footer_head = struct.pack("<BQQQ", Op.FOOTER, 20, summary_start, summary_offset_start)
        crc = zlib.crc32(bytes(summary) + bytes(offsets) + footer_head)
        self._write(bytes(summary) + bytes(offsets) + footer_head + struct.pack("<I", crc) + MAGIC)
        self.stream.flush()
        self.stream.close()


class BagWriter:
    """Write a rosbag2 bag directory with MCAP storage from already serialized (CDR) messages.

    ``path`` is the bag directory (created; it must not exist or be empty). ``compression`` is one
    of ``zstd`` (default), ``lz4``, ``none``; ``chunk_size`` the uncompressed bytes per chunk. A new
    file is started when the current one reaches ``max_file_size`` bytes (checked after each chunk)
    or when a message is ``max_file_duration_ns`` or more after the file's first message (0: no
    limit). Not thread safe: call it from one thread (or hold a lock).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        compression: str = "zstd",
        compression_level: int = 3,
        chunk_size: int = 1 << 20,
        max_file_size: int = 0,
        max_file_duration_ns: int = 0,
        ros_distro: str | None = None,
        custom_data: dict[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        if compression not in COMPRESSIONS:
            raise WriterStateError(self.path, f"compression {compression!r} not in {COMPRESSIONS}")
        if chunk_size <= 0 or max_file_size < 0 or max_file_duration_ns < 0:
            raise WriterStateError(
                self.path,
                f"chunk_size={chunk_size} must be > 0, max_file_size={max_file_size} and "
                f"max_file_duration_ns={max_file_duration_ns} >= 0",
            )
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise WriterStateError(self.path, "the bag path exists and is not an empty directory")
        self.path.mkdir(parents=True, exist_ok=True)
        self.compression = compression
        self.compression_level = compression_level
        self.chunk_size = chunk_size
        self.max_file_size = max_file_size
        self.max_file_duration_ns = max_file_duration_ns
        self.ros_distro = ros_distro or ros_distro_in_use()
        self.custom_data = dict(custom_data or {})
        self._topics: dict[str, _Topic] = {}
        self._files: list[_FileStats] = []
        self._file: _McapFile | None = None
        self._closed = False
        self._open_next_file()

    # ------------------------------------------------------------------ public API

    def add_topic(
        self,
        name: str,
        type_name: str,
        qos_profiles_yaml: str | None = None,
        *,
        schema_text: str | None = None,
        type_hash: str | None = None,
    ) -> None:
        """Declare a topic before writing to it; ``type_name`` is ``pkg/msg/Type`` or ``pkg/Type``.

        The schema is built from the installed .msg files unless ``schema_text`` (ros2msg) is given;
        ``qos_profiles_yaml`` is the offered QoS profiles as rosbag2 stores them (default: one
        reliable, volatile profile).
        """
        self._check_open()
        if name in self._topics:
            known = self._topics[name]
            if known.type != normalize_type(type_name):
                raise WriterStateError(
                    self.path, f"topic {name} already added with type {known.type}, not {type_name}"
                )
            return
        full = normalize_type(type_name)
        topic = _Topic(
            name=name,
            type=full,
            qos_yaml=default_qos_yaml() if qos_profiles_yaml is None else qos_profiles_yaml,
            schema_text=ros2msg_schema(full) if schema_text is None else schema_text,
            type_hash=type_description_hash(full) if type_hash is None else type_hash,
        )
        self._topics[name] = topic
        assert self._file is not None
        self._file.add_channel(topic)

    def write(
        self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None
    ) -> None:
        """Append one serialized message (CDR with its 4-byte encapsulation header)."""
        file = self._file
        if file is None:
            self._check_open()
            file = self._open_next_file()
        channel = file.channels.get(topic)
        if channel is None:
            raise WriterStateError(self.path, f"write to topic {topic!r} before add_topic()")
        stats = self._files[-1]
        if (
            self.max_file_duration_ns
            and stats.start is not None
            and log_time_ns - stats.start >= self.max_file_duration_ns
        ):
            self._split()
            file = self._open_next_file()
            channel = file.channels[topic]
            stats = self._files[-1]
        file.add_message(
            channel, data, log_time_ns, log_time_ns if publish_time_ns is None else publish_time_ns
        )
        channel.topic.count += 1
        stats.count += 1
        if stats.start is None or log_time_ns < stats.start:
            stats.start = log_time_ns
        if stats.end is None or log_time_ns > stats.end:
            stats.end = log_time_ns
        if len(file.chunk) >= self.chunk_size:
            file.finish_chunk()
            if self.max_file_size and file.offset >= self.max_file_size:
                self._split()

    def flush(self) -> None:
        """Write the open chunk now (smaller chunks compress worse; chunks flush by themselves)."""
        if self._file is not None:
            self._file.finish_chunk()

    def close(self) -> None:
        """Finish the open file and write the final metadata.yaml. Idempotent."""
        if self._closed:
            return
        if self._file is not None:
            self._file.close(self._metadata_yaml(inner=True), self.ros_distro)
            self._file = None
        self._closed = True
        self._write_metadata()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def files(self) -> list[Path]:
        return [f.path for f in self._files]

    # ------------------------------------------------------------------ internals

    def _check_open(self) -> None:
        if self._closed:
            raise WriterStateError(self.path, "the writer is closed")

    def _open_next_file(self) -> _McapFile:
        path = self.path / f"{self.path.name}_{len(self._files)}.mcap"
        file = _McapFile(path, self.compression, self.compression_level)
        self._files.append(_FileStats(path))
        for topic in self._topics.values():
            file.add_channel(topic)
        self._file = file
        self._write_metadata()
        return file

    def _split(self) -> None:
        assert self._file is not None
        self._file.close(self._metadata_yaml(inner=True), self.ros_distro)
        self._file = None
        self._write_metadata()

    def _metadata_yaml(self, inner: bool = False) -> str:
        data = bag_metadata(
            self._files, list(self._topics.values()), self.custom_data, self.ros_distro
        )
        return metadata_yaml(data, inner)

    def _write_metadata(self) -> None:
        write_metadata_file(self.path, self._metadata_yaml())


def bag_metadata(
    files: list[_FileStats], topics: list[_Topic], custom_data: dict[str, str], ros_distro: str
) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping (version 9) of a bag."""
    starts = [f.start for f in files if f.start is not None]
    ends = [f.end for f in files if f.end is not None]
    start = min(starts) if starts else 0
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": (max(ends) - start) if ends else 0},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": sum(f.count for f in files),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": yaml.safe_load(t.qos_yaml) or [],
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.count,
            }
            for t in topics
        ],
        # Chunk compression is internal to the MCAP storage, as with rosbag2's storage presets.
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f.path.name for f in files],
        "files": [
            {
                "path": f.path.name,
                "starting_time": {"nanoseconds_since_epoch": f.start or 0},
                "duration": {
                    "nanoseconds": (f.end - f.start)
                    if f.start is not None and f.end is not None
                    else 0
                },
                "message_count": f.count,
            }
            for f in files
        ],
        "custom_data": dict(custom_data),
        "ros_distro": ros_distro,
    }


def metadata_yaml(data: dict[str, Any], inner: bool = False) -> str:
    """metadata.yaml text (``inner``: without the top-level key, as in the MCAP metadata record)."""
    if not inner:
        data = {"rosbag2_bagfile_information": data}
    return str(yaml.safe_dump(data, sort_keys=False, default_flow_style=False))


def write_metadata_file(directory: Path, text: str) -> None:
    """Replace ``directory/metadata.yaml`` atomically (temp file, fsync, rename)."""
    target = directory / "metadata.yaml"
    tmp = target.with_name("metadata.yaml.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, target)
