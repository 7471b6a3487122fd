"""Rebuild a bag's metadata.yaml from its data, and finish MCAP files whose writer was killed.

A writer killed with SIGKILL leaves ``metadata.yaml`` with the counts of its last split (or start)
and a last MCAP file without summary and footer. ``reindex`` (like ``ros2 bag reindex``) counts the
messages of every file and rewrites metadata.yaml; with ``finish_files`` (default) it also rewrites
each cut-short file from its readable messages, with summary and footer, so that readers which need
a summary (rosbags, tools that seek by chunk index) accept the bag again.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from feeder_ros.bag.errors import BagProblem, MissingBagError
from feeder_ros.bag.reader import Bag, BagInfo, bag_info
from feeder_ros.bag.scan import ChannelInfo, FileScan
from feeder_ros.bag.schemas import type_description_hash
from feeder_ros.bag.writer import (
    _FileStats,
    _McapFile,
    _Topic,
    bag_metadata,
    default_qos_yaml,
    metadata_yaml,
    write_metadata_file,
)

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


def _count(
    path: Path, report: Callable[[BagProblem], None], topics: dict[str, _Topic]
) -> tuple[_FileStats, bool]:
    """Messages per topic and time range of one file (from its indexes); is the file complete?"""
    stats = _FileStats(path)
    scan = FileScan(path, report)
    for chunk in scan.chunks(lambda _c: True, decode=False):
        for cid, times in chunk.log_times.items():
            if len(times) == 0:
                continue
            channel = scan.channels[cid]
            topic = topics.setdefault(channel.topic, _topic_of(channel))
            topic.count += len(times)
            stats.count += len(times)
            lo, hi = int(times.min()), int(times.max())
            stats.start = lo if stats.start is None else min(stats.start, lo)
            stats.end = hi if stats.end is None else max(stats.end, hi)
    for channel in scan.channels.values():
        topics.setdefault(channel.topic, _topic_of(channel))
    return stats, scan.complete


def _finish(path: Path, bag: Bag, compression: str, meta_text: str, distro: str) -> None:
    """Rewrite a cut-short file from its readable messages, with summary and footer."""
    tmp = path.with_name(path.name + ".reindex")
    tmp.unlink(missing_ok=True)
    out = _McapFile(tmp, compression, 3)

    def report(problem: BagProblem) -> None:
        if problem not in bag.problems:  # the counting pass found it already
            bag.report(problem)

    scan = FileScan(path, report)
    topics: dict[int, _Topic] = {}
    try:
        for chunk in scan.chunks(lambda _c: True):
            for cid, log, pub, data in chunk.messages():
                topic = topics.get(cid)
                if topic is None:
                    topic = _topic_of(scan.channels[cid])
                    topics[cid] = topic
                    out.add_channel(topic)
                out.add_message(out.channels[topic.name], data, log, pub)
                if len(out.chunk) >= 1 << 20:
                    out.finish_chunk()
        out.close(meta_text, distro)
    except BaseException:
        out.stream.close()
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)


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
    distro = str(old.get("ros_distro") or os.environ.get("ROS_DISTRO", "kilted"))
    topics: dict[str, _Topic] = {}
    files: list[_FileStats] = []
    cut_short: list[int] = []
    for file in bag.files:
        stats, complete = _count(file, bag.report, topics)
        files.append(stats)
        if not complete:
            cut_short.append(len(files) - 1)
    if finish_files and cut_short:
        meta_text = metadata_yaml(bag_metadata(files, list(topics.values()), custom, distro), True)
        for index in cut_short:
            _finish(files[index].path, bag, compression, meta_text, distro)
        topics = {}  # count again: unreadable chunks of the cut-short files were dropped
        files = [_count(file, lambda _p: None, topics)[0] for file in bag.files]
    write_metadata_file(
        directory, metadata_yaml(bag_metadata(files, list(topics.values()), custom, distro))
    )
    problems: list[BagProblem] = list(bag.problems)
    info = bag_info(Bag(directory, warn=False))
    info.problems = problems + info.problems
    return info
