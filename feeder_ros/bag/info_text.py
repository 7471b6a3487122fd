"""What a bag holds, as text for a person and as a JSON-ready dict (``feeder info``, ``feeder
reindex``): files, time range, topics with types and counts, and the problems found."""

from __future__ import annotations

import datetime
from typing import Any

from feeder_ros.bag.reader import BagInfo

__all__ = ["describe_info", "info_as_dict"]


def _when(ns: int | None) -> str:
    if ns is None:
        return "-"
    stamp = datetime.datetime.fromtimestamp(ns * 1e-9, tz=datetime.UTC)
    seconds, nanoseconds = divmod(ns, 10**9)
    return f"{stamp.isoformat(timespec='milliseconds')} ({seconds}.{nanoseconds:09d} s)"


def describe_info(info: BagInfo) -> str:
    """Lines like ``ros2 bag info``'s, then the problems, the lost data first."""
    lost = info.lost_data()
    topics = sorted(info.topics.values(), key=lambda t: t.name)
    lines = [
        f"Bag:       {info.path}",
        f"Files:     {', '.join(p.name for p in info.files) or '-'}",
        f"Duration:  {info.duration_ns * 1e-9:.3f} s",
        f"Start:     {_when(info.start_ns)}",
        f"End:       {_when(info.end_ns)}",
        f"Messages:  {info.message_count}",
        f"Topics:    {len(topics)}",
    ]
    width = max((len(t.name) for t in topics), default=0)
    type_width = max((len(t.type) for t in topics), default=0)
    for topic in topics:
        lines.append(
            f"  {topic.name:<{width}}  {topic.type:<{type_width}}  {topic.message_count} msgs"
        )
    if lost:
        lines.append(f"DATA LOST: {len(lost)} problem(s) lost recorded messages")
    elif info.cut_short:
        lines.append(
            "cut short: the last file has no summary (a recorder killed?); "
            "`feeder reindex` finishes it"
        )
    if info.problems:
        lines.append(f"Problems:  {len(info.problems)}")
        lines.extend(f"  {p}" for p in [*lost, *(p for p in info.problems if p not in lost)])
    return "\n".join(lines)


def info_as_dict(info: BagInfo) -> dict[str, Any]:
    """The same as plain data: times in ns (None when the bag has no messages)."""
    lost = info.lost_data()
    return {
        "path": str(info.path),
        "files": [p.name for p in info.files],
        "start_ns": info.start_ns,
        "end_ns": info.end_ns,
        "duration_s": info.duration_ns * 1e-9,
        "message_count": info.message_count,
        "topics": [
            {
                "name": t.name,
                "type": t.type,
                "message_count": t.message_count,
                "first_ns": t.first_ns,
                "last_ns": t.last_ns,
            }
            for t in sorted(info.topics.values(), key=lambda t: t.name)
        ],
        "cut_short": info.cut_short,
        "data_lost": bool(lost),
        "problems": [
            {"kind": p.kind, "text": str(p), "data_lost": p in lost} for p in info.problems
        ],
    }
