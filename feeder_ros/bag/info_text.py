"""What a bag holds, as text for a person and as a JSON-ready dict (``feeder info``, ``feeder
reindex``): files, time range, topics with types and counts, how many recorded messages are lost
(in total and per topic), the feeders it holds, what was checked, and the problems found."""

from __future__ import annotations

import datetime
from typing import Any

from feeder_ros.bag.feeders import feeder_namespace
from feeder_ros.bag.loss import LossCount
from feeder_ros.bag.reader import BagInfo, Checks

__all__ = ["describe_info", "feeders_of", "info_as_dict"]

#: what ``feeder info --verify`` adds to the default reading (printed without it)
VERIFY_ADDS = (
    "--verify also decompresses every chunk, checks its CRC, checks every message record "
    "against its index and decodes every message"
)


def _when(ns: int | None) -> str:
    if ns is None:
        return "-"
    stamp = datetime.datetime.fromtimestamp(ns * 1e-9, tz=datetime.UTC)
    seconds, nanoseconds = divmod(ns, 10**9)
    return f"{stamp.isoformat(timespec='milliseconds')} ({seconds}.{nanoseconds:09d} s)"


def feeders_of(info: BagInfo) -> list[str]:
    """The namespaces of the feeders whose topics the bag holds (by their relative names)."""
    found = {feeder_namespace(t.name, t.type or None) for t in info.topics.values()}
    return sorted(ns for ns in found if ns is not None)


def _messages_line(info: BagInfo, loss: LossCount | None) -> str:
    line = f"Messages:  {info.message_count}"
    if loss is None:
        return line
    if loss.exact and loss.lost:
        return f"{line} readable of {loss.recorded} recorded: {loss.lost} LOST"
    if not loss.exact:
        return f"{line} readable; how many were recorded is unknown" + (
            f" ({loss.lost} at least LOST)" if loss.lost else ""
        )
    return line


def _checks_line(checks: Checks) -> str:
    chunks = f"{checks.chunks} chunk(s) in {checks.files} file(s)"
    if checks.verified:
        return (
            f"Verified:  {chunks}: {checks.decompressed} decompressed, "
            f"{checks.crc_checked} CRC-32 and {checks.frame_checked} zstd checksum(s) checked, "
            f"{checks.located} message record(s) checked against their index, "
            f"{checks.decoded} message(s) decoded"
            + (f" ({checks.undecodable} without a known definition)" if checks.undecodable else "")
        )
    return (
        f"Checked:   {chunks}, counted from their message indexes "
        f"({checks.decompressed} decompressed where needed); {VERIFY_ADDS}"
    )


def describe_info(info: BagInfo) -> str:
    """Lines like ``ros2 bag info``'s, the loss and what was checked, then the problems, the lost
    data first."""
    lost = info.lost_data()
    loss = info.loss
    topics = sorted(info.topics.values(), key=lambda t: t.name)
    lines = [
        f"Bag:       {info.path}",
        f"Files:     {', '.join(p.name for p in info.files) or '-'}",
        f"Duration:  {info.duration_ns * 1e-9:.3f} s",
        f"Start:     {_when(info.start_ns)}",
        f"End:       {_when(info.end_ns)}",
        _messages_line(info, loss),
        f"Topics:    {len(topics)}",
    ]
    lost_by_topic = {} if loss is None else {t.topic: t for t in loss.lost_topics()}
    width = max((len(t.name) for t in topics), default=0)
    type_width = max((len(t.type) for t in topics), default=0)
    for topic in topics:
        row = f"  {topic.name:<{width}}  {topic.type:<{type_width}}  {topic.message_count} msgs"
        gone = lost_by_topic.get(topic.name)
        if gone is not None:
            row += f" of {gone.recorded} recorded: {gone.lost} LOST"
        lines.append(row)
    feeders = feeders_of(info)
    if len(feeders) > 1:
        lines.append(
            f"Feeders:   {len(feeders)} ({', '.join(feeders)}); `feeder analyze` analyses each "
            "on its own (--namespace NS: one)"
        )
    if lost:
        counted = loss is not None and (loss.lost or not loss.exact)
        lines.append(
            "DATA LOST: "
            + (f"{loss.describe()}; " if loss is not None and counted else "")
            + f"{len(lost)} problem(s) lost recorded messages"
        )
    elif info.cut_short:
        lines.append(
            "cut short: the last file has no summary (a recorder killed?); "
            "`feeder reindex` finishes it"
            + ("" if loss is None or loss.exact else f"; {loss.describe()}")
        )
    if info.checks is not None:
        lines.append(_checks_line(info.checks))
    if info.problems:
        lines.append(f"Problems:  {len(info.problems)}")
        lines.extend(f"  {p}" for p in [*lost, *(p for p in info.problems if p not in lost)])
    return "\n".join(lines)


def info_as_dict(info: BagInfo) -> dict[str, Any]:
    """The same as plain data: times in ns (None when the bag has no messages); ``loss`` the
    recorded, readable and lost messages in total and per topic (``lost_messages``: the total lost,
    a lower bound when ``loss.total_known`` is false)."""
    lost = info.lost_data()
    checks = info.checks
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
        "feeders": feeders_of(info),
        "cut_short": info.cut_short,
        "data_lost": bool(lost),
        "lost_messages": None if info.loss is None else info.loss.lost,
        "loss": None if info.loss is None else info.loss.as_dict(),
        "checked": None
        if checks is None
        else {
            "verified": checks.verified,
            "files": checks.files,
            "chunks": checks.chunks,
            "chunks_decompressed": checks.decompressed,
            "crc_checked": checks.crc_checked,
            "zstd_checksums_checked": checks.frame_checked,
            "message_records_checked": checks.located,
            "messages_decoded": checks.decoded,
            "messages_not_decodable": checks.undecodable,
        },
        "problems": [
            {"kind": p.kind, "text": str(p), "data_lost": p in lost} for p in info.problems
        ],
    }
