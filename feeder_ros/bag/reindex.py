"""Rebuild a bag's metadata.yaml from its data, and finish MCAP files whose writer was killed.

A writer killed with SIGKILL leaves ``metadata.yaml`` with the counts of its last split (or start)
and a last MCAP file without summary and footer. ``reindex`` (like ``ros2 bag reindex``) counts the
messages of every file and rewrites metadata.yaml; with ``finish_files`` (default) it also rewrites
each cut-short file from its readable messages, with summary and footer, so that readers which need
a summary (rosbags, tools that seek by chunk index) accept the bag again.

Nothing that could still be read is destroyed: only a file whose one problem is its missing end is
rewritten (its incomplete last record is all it loses). A file damaged otherwise (not MCAP, a
corrupt chunk or record, unreadable) is left byte for byte as it is, with a ``not_finished``
problem naming why, and a split file listed in metadata.yaml but missing stays listed (with what the
old metadata.yaml said of it), so the bag keeps saying that part of the recording is gone.

The messages the bag lost (the old metadata.yaml's and the files' own counts against what can be
read, :mod:`feeder_ros.bag.loss`) are counted before the rewrite and kept in the new metadata.yaml's
``custom_data``: a repaired bag still says how many recorded messages it lost.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from feeder_ros.bag.errors import BagProblem, MissingBagError
from feeder_ros.bag.loss import (
    LOST_BY_TOPIC_KEY,
    LOST_KEY,
    FileCount,
    count_loss,
    file_count,
    lost_custom_data,
)
from feeder_ros.bag.reader import Bag, BagInfo, _file_index, bag_info
from feeder_ros.bag.scan import ChannelInfo, FileScan
from feeder_ros.bag.schemas import type_description_hash
from feeder_ros.bag.writer import (
    _Channel,
    _FileStats,
    _McapFile,
    _Topic,
    bag_metadata,
    default_qos_yaml,
    metadata_yaml,
    write_metadata_file,
)
from feeder_ros.ros_compat import ros_distro as ros_distro_in_use

__all__ = ["reindex"]


def _topic_of(channel: ChannelInfo) -> _Topic:
    qos = channel.metadata.get("offered_qos_profiles")
    type_hash = channel.metadata.get("topic_type_hash") or (
        type_description_hash(channel.type) if channel.type else ""
    )
    return _Topic(
        name=channel.topic,
        type=channel.type,
        qos_yaml=default_qos_yaml() if qos is None else qos,
        schema_text=channel.schema_text,
        type_hash=type_hash,
    )


#: problems after which a cut-short file is still rewritten: they concern single messages, which
#: the rewrite copies byte for byte
#: (the messages of a chunk the file's end cut off are lost with or without the rewrite)
_HARMLESS_TO_REWRITE = frozenset(
    {"cut_short", "cut_chunk", "malformed_message", "unsupported_encoding"}
)


def _count(
    path: Path, report: Callable[[BagProblem], None], topics: dict[str, _Topic]
) -> tuple[_FileStats, FileCount]:
    """Messages per topic and time range of one file (from its indexes), and its counts for the
    loss (``FileCount.complete``: the file is complete). ``topics`` is keyed by name and type:
    one name may carry two types."""
    stats = _FileStats(path)
    scan = FileScan(path, report)
    for chunk in scan.chunks(lambda _c: True, decode=False):
        for cid, times in chunk.log_times.items():
            if len(times) == 0:
                continue
            channel = scan.channels[cid]
            topic = topics.setdefault(f"{channel.topic}\0{channel.type}", _topic_of(channel))
            topic.count += len(times)
            stats.count += len(times)
            lo, hi = int(times.min()), int(times.max())
            stats.start = lo if stats.start is None else min(stats.start, lo)
            stats.end = hi if stats.end is None else max(stats.end, hi)
    for channel in scan.channels.values():
        topics.setdefault(f"{channel.topic}\0{channel.type}", _topic_of(channel))
    return stats, file_count(scan)


def _finish(path: Path, bag: Bag, compression: str, meta_text: str, distro: str) -> None:
    """Rewrite a cut-short file from its readable messages, with summary and footer; if reading
    every chunk finds damage the counting pass could not see (a corrupt chunk: counting reads
    only the indexes), the file is left as it is instead."""
    tmp = path.with_name(path.name + ".reindex")
    tmp.unlink(missing_ok=True)
    out = _McapFile(tmp, compression, 1 << 20)
    damage: set[str] = set()

    def report(problem: BagProblem) -> None:
        if problem.kind not in _HARMLESS_TO_REWRITE:
            damage.add(problem.kind)
        if problem not in bag.problems:  # the counting pass found it already
            bag.report(problem)

    scan = FileScan(path, report)
    channels: dict[int, _Channel] = {}  # by the channel id in the old file
    try:
        for chunk in scan.chunks(lambda _c: True):
            for cid, log, pub, data in chunk.messages():
                channel = channels.get(cid)
                if channel is None:
                    channel = out.add_channel(_topic_of(scan.channels[cid]))
                    channels[cid] = channel
                out.add_message(channel, data, log, pub)
        out.close(meta_text, distro)
    except BaseException:
        out.stream.close()
        tmp.unlink(missing_ok=True)
        raise
    if damage:
        tmp.unlink()
        bag.report(_not_finished(path, damage))
        return
    os.replace(tmp, path)


def _not_finished(path: Path, damage: set[str]) -> BagProblem:
    return BagProblem(
        "not_finished",
        path,
        f"left unchanged, without a footer: damaged ({', '.join(sorted(damage))}), not only cut "
        "short; a rewrite would drop what is past the damage",
    )


def _keep_missing(meta: dict[str, Any], old: dict[str, Any], bag: Bag) -> None:
    """List again the files the old metadata.yaml listed that are missing, with its entries for
    them (the messages counted in ``meta`` are those present)."""
    missing = {p.file.name for p in bag.problems if p.kind == "missing_file" and p.file}
    if not missing:
        return
    entries = {}
    for entry in old.get("files") or []:
        try:
            entries[Path(str(entry["path"])).name] = dict(entry)
        except (KeyError, TypeError, ValueError):
            continue
    names = [*meta["relative_file_paths"], *sorted(missing)]
    names.sort(key=lambda n: _file_index(Path(n)))
    by_name = {e["path"]: e for e in meta["files"]}
    meta["relative_file_paths"] = names
    meta["files"] = [
        by_name.get(n)
        or entries.get(n)
        or {
            "path": n,
            "starting_time": {"nanoseconds_since_epoch": 0},
            "duration": {"nanoseconds": 0},
            "message_count": 0,
        }
        for n in names
    ]


def reindex(
    path: str | os.PathLike[str], *, finish_files: bool = True, compression: str = "zstd"
) -> BagInfo:
    """Rewrite ``metadata.yaml`` of the bag directory ``path`` from the data in its MCAP files.

    With ``finish_files``, every file without a footer is rewritten (its readable messages, with
    summary and footer; unreadable chunks are dropped and reported). Returns the info of the
    reindexed bag; ``problems`` lists what was found in the files before the rewrite.
    """
    directory = Path(path)
    if not directory.is_dir():
        raise MissingBagError(directory, "reindex needs a bag directory")
    bag = Bag(directory, warn=False)
    old = bag.metadata or {}
    custom = {str(k): str(v) for k, v in (old.get("custom_data") or {}).items()}
    distro = str(old.get("ros_distro") or ros_distro_in_use())
    topics: dict[str, _Topic] = {}
    files: list[_FileStats] = []
    counts: list[FileCount] = []
    cut_short: list[int] = []
    for file in bag.files:
        found: list[BagProblem] = []

        def report(problem: BagProblem, found: list[BagProblem] = found) -> None:
            found.append(problem)
            bag.report(problem)

        stats, count = _count(file, report, topics)
        files.append(stats)
        counts.append(count)
        if count.complete:
            continue
        damage = {p.kind for p in found} - _HARMLESS_TO_REWRITE
        if not damage:
            cut_short.append(len(files) - 1)
        elif finish_files:
            bag.report(_not_finished(file, damage))
    missing = [p.file for p in bag.problems if p.kind == "missing_file" and p.file]
    loss = count_loss(bag.metadata, counts, missing)
    custom = {k: v for k, v in custom.items() if k not in (LOST_KEY, LOST_BY_TOPIC_KEY)}
    custom.update(lost_custom_data(loss))
    if finish_files and cut_short:
        meta_text = metadata_yaml(bag_metadata(files, list(topics.values()), custom, distro), True)
        for index in cut_short:
            _finish(files[index].path, bag, compression, meta_text, distro)
        topics = {}  # count again: unreadable chunks of the cut-short files were dropped
        files = [_count(file, lambda _p: None, topics)[0] for file in bag.files]
    meta = bag_metadata(files, list(topics.values()), custom, distro)
    _keep_missing(meta, old, bag)
    write_metadata_file(directory, metadata_yaml(meta))
    info = bag_info(Bag(directory, warn=False))  # counts the loss the new metadata.yaml keeps
    info.problems = list(bag.problems) + info.problems
    return info
