"""``BagWriter``: record serialized ROS 2 messages into a rosbag2 bag (MCAP storage), without ROS.

The bag is a directory ``<name>/`` with ``metadata.yaml`` (rosbag2 ``version: 9``) and the MCAP
files ``<name>_0.mcap``, ``<name>_1.mcap``, ... (profile ``ros2``, ``ros2msg`` schemas with every
dependent definition, ``cdr`` messages, channel metadata ``offered_qos_profiles``), written by the
``mcap`` library's writer: messages in chunks (zstd, lz4 or uncompressed) with CRCs, each followed
by its message indexes; the summary, the ``rosbag2`` metadata record and the footer when a file is
closed. What ``mcap`` does not do is here: rosbag2's directory, metadata and splitting, and the
crash safety below.

Crash safety: every finished chunk and its indexes are handed to the operating system as they are
written (no Python buffer), and ``metadata.yaml`` is written when the bag starts and rewritten
(temp file + rename) on each split and on ``close``. A writer killed with SIGKILL leaves every
complete chunk on disk; the reader reports the last file as cut short and reads it up to its last
complete chunk. Chunks are not fsynced: data in the page cache survives a killed process, not a
power cut.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any, cast

import yaml
from mcap.writer import CompressionType, Writer

from feeder_ros.bag.errors import WriterStateError
from feeder_ros.bag.msgdef import normalize_type
from feeder_ros.bag.schemas import ros2msg_schema, type_description_hash
from feeder_ros.ros_compat import ros_distro as ros_distro_in_use

__all__ = ["COMPRESSIONS", "METADATA_VERSION", "BagWriter", "default_qos_yaml"]

METADATA_VERSION = 9
COMPRESSIONS = ("zstd", "lz4", "none")
LIBRARY = "feeder_ros.bag"
_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
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
    sequence: int = 0


class _DirectFile(io.BufferedIOBase):
    """A new file whose every ``write`` goes to the operating system at once (no Python buffer):
    ``mcap``'s writer hands over each finished chunk, then its message indexes, as whole writes,
    so a killed recorder leaves every finished chunk on disk (up to the page cache)."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self._raw = open(path, "xb", buffering=0)  # noqa: SIM115 - closed in close()
        self.size = 0

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        done = 0
        while done < len(view):
            done += self._raw.write(view[done:]) or 0
        self.size += done
        return done

    def tell(self) -> int:
        return self.size

    def flush(self) -> None:
        pass  # nothing is held here

    def close(self) -> None:
        if not self.closed:
            self._raw.close()
        super().close()


class _McapFile:
    """One MCAP file being written through ``mcap``'s :class:`~mcap.writer.Writer` (chunks of
    ``chunk_size`` uncompressed bytes, message and chunk indexes, CRCs, statistics, summary); the
    ``rosbag2`` metadata record and the footer are written by :meth:`close`.

    ``mcap`` writes a channel's (and its schema's) record into the open chunk. A channel is
    therefore registered with its first message, at the start of a new chunk, so that the chunk
    holding its record also lists it in its message indexes: a reader skipping chunks by their
    indexes (a cut file has no summary listing the channels) cannot skip the record. Channels
    without a message are registered at :meth:`close` and listed in the summary."""

    def __init__(self, path: Path, compression: str, chunk_size: int) -> None:
        self.path = path
        self.stream = _DirectFile(path)
        self._writer = Writer(
            cast(IO[Any], self.stream),  # a BufferedIOBase: mcap writes to it as it is
            chunk_size=chunk_size,
            compression=_COMPRESSION[compression],
        )
        self._writer.start(profile="ros2", library=LIBRARY)
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, _Channel] = {}  # by topic name (the latest channel of a name)
        self._unregistered: list[_Channel] = []

    @property
    def size(self) -> int:
        """Bytes written so far (finished chunks and their indexes)."""
        return self.stream.size

    def add_channel(self, topic: _Topic) -> _Channel:
        channel = _Channel(0, topic)  # id 0: not registered yet
        self.channels[topic.name] = channel
        self._unregistered.append(channel)
        return channel

    def _register(self, channel: _Channel) -> None:
        # the open chunk is written first: mcap writes a chunk once it is full, and one filled
        # by these records alone would be written without the message that lists the channel
        # (a chunk without messages is not written: the records wait for that message)
        self._writer.flush()  # type: ignore[no-untyped-call]
        topic = channel.topic
        schema_id = self.schemas.get(topic.type)
        if schema_id is None:
            raw = topic.schema_text.encode("utf-8")
            schema_id = self._writer.register_schema(topic.type, "ros2msg", raw)
            self.schemas[topic.type] = schema_id
        metadata = {"offered_qos_profiles": topic.qos_yaml, "topic_type_hash": topic.type_hash}
        channel.id = self._writer.register_channel(topic.name, "cdr", schema_id, metadata)
        self._unregistered.remove(channel)

    def add_message(self, channel: _Channel, data: bytes, log_time: int, publish_time: int) -> None:
        if not channel.id:
            self._register(channel)
        self._writer.add_message(channel.id, log_time, data, publish_time, channel.sequence)
        channel.sequence = (channel.sequence + 1) & 0xFFFFFFFF

    def finish_chunk(self) -> None:
        """Write the open chunk and its message indexes now."""
        self._writer.flush()  # type: ignore[no-untyped-call]

    def close(self, metadata_yaml: str, ros_distro: str) -> None:
        """Finish the data section (with the ``rosbag2`` metadata record), summary and footer."""
        for channel in list(self._unregistered):
            self._register(channel)
        metadata = {"serialized_metadata": metadata_yaml, "ROS_DISTRO": ros_distro}
        self._writer.add_metadata("rosbag2", metadata)
        self._writer.finish()  # type: ignore[no-untyped-call]
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
        if self.max_file_size and file.size >= self.max_file_size:
            self._split()  # the size grows as chunks are written

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
        file = _McapFile(path, self.compression, self.chunk_size)
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
