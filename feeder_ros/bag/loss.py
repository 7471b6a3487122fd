"""How many recorded messages a bag lost: what was recorded, as the bag itself counts it, against
what can be read.

What was recorded is counted, for each file, from the best count the bag holds: the statistics in
the file's MCAP summary (a complete file), else the message indexes of the chunks a reader had to
skip plus the messages still found in the readable part of a chunk that the file's end cut off (a
lower bound); and for the whole bag from ``metadata.yaml`` (per topic, per file and in total; the
writer rewrites it when a file is finished, so a truncated copy of a finished bag still says what
it held). The largest count of each is taken. A file cut short (no summary) that ``metadata.yaml``
does not count either (a recorder killed before it finished the file) leaves the total unknown: the
lost count is then a lower bound, and ``LossCount.unknown`` says why.

``feeder reindex`` rewrites metadata.yaml from the data; it keeps the loss it found there
(``custom_data``: :data:`LOST_KEY`, :data:`LOST_BY_TOPIC_KEY`), so a repaired bag still says what
it lost.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from feeder_ros.bag.errors import BagProblem
from feeder_ros.bag.scan import FileScan

__all__ = [
    "LOST_BY_TOPIC_KEY",
    "LOST_KEY",
    "FileCount",
    "LossCount",
    "TopicLoss",
    "count_loss",
    "file_count",
    "lost_custom_data",
]

#: metadata.yaml ``custom_data`` keys where ``feeder reindex`` keeps the loss it found
LOST_KEY = "feeder_ros.lost_messages"
LOST_BY_TOPIC_KEY = "feeder_ros.lost_messages_by_topic"
#: the topic name under which messages of an undefined channel are counted
UNKNOWN_TOPIC = "(undefined channel)"
_TOPICS_NAMED = 6  # topics named in a problem's text; the rest summed


@dataclass(frozen=True)
class FileCount:
    """One file's messages per topic as a pass over it found them."""

    path: Path
    readable: dict[str, int]  # messages located in readable chunks
    lost: dict[str, int]  # messages of skipped chunks and of a chunk the file's end cut off
    recorded: dict[str, int] | None  # the summary statistics' count per topic (None: not read)
    recorded_total: int | None  # the summary statistics' total (None: no statistics read)
    complete: bool  # the footer was reached
    uncounted_chunks: int  # skipped or cut-off chunks whose messages nothing counts

    @property
    def floor(self) -> int:
        """Messages the file's own records show were recorded (all of them if it has a summary)."""
        seen = sum(self.readable.values()) + sum(self.lost.values())
        return max(seen, self.recorded_total or 0)


def file_count(scan: FileScan) -> FileCount:
    """The counts of a scan that has been read to its end."""

    def by_topic(counts: Mapping[int, int]) -> dict[str, int]:
        out: dict[str, int] = {}
        for cid, n in counts.items():
            channel = scan.channels.get(cid)
            topic = channel.topic if channel is not None else UNKNOWN_TOPIC
            out[topic] = out.get(topic, 0) + n
        return out

    stats = scan.statistics
    per_channel = None if stats is None else stats["channel_message_counts"]
    recorded = None if per_channel is None else by_topic(per_channel)
    return FileCount(
        path=scan.path,
        readable=by_topic(scan.tally.readable),
        lost=by_topic(scan.tally.lost),
        recorded=recorded,
        recorded_total=None if stats is None else int(stats["message_count"]),
        complete=scan.complete,
        uncounted_chunks=scan.tally.uncounted_chunks,
    )


@dataclass(frozen=True)
class TopicLoss:
    topic: str
    recorded: int  # as the bag counts it (a lower bound unless ``LossCount.exact``)
    readable: int

    @property
    def lost(self) -> int:
        return max(self.recorded - self.readable, 0)


@dataclass(frozen=True)
class LossCount:
    """Messages recorded (as far as the bag counts them) and readable, in total and per topic."""

    recorded: int
    readable: int
    #: the recorded count is complete: every file is counted (summary or metadata.yaml)
    exact: bool
    topics: tuple[TopicLoss, ...]
    #: where the recorded counts come from ("metadata.yaml", "MCAP summaries", ...)
    sources: tuple[str, ...]
    #: why the recorded total is unknown (``exact`` False): one reason per file
    unknown: tuple[str, ...] = ()
    #: of ``lost``, the messages lost before a ``feeder reindex`` (kept in metadata.yaml)
    lost_before_reindex: int = 0

    @property
    def lost(self) -> int:
        """Messages recorded but not readable (a lower bound unless ``exact``)."""
        return max(self.recorded - self.readable, 0)

    def lost_topics(self) -> list[TopicLoss]:
        return sorted((t for t in self.topics if t.lost), key=lambda t: (-t.lost, t.topic))

    def describe(self) -> str:
        """One line: "28454 of 54164 recorded messages lost (counted from metadata.yaml)"."""
        source = f"counted from {', '.join(self.sources)}" if self.sources else "no count"
        if self.exact:
            if not self.lost:
                return f"none of {self.recorded} recorded messages lost ({source})"
            share = 100.0 * self.lost / self.recorded if self.recorded else 100.0
            text = (
                f"{self.lost} of {self.recorded} recorded messages lost ({share:.3g} %; {source})"
            )
        elif self.lost:
            text = (
                f"at least {self.lost} recorded message(s) lost ({source}); how many were "
                f"recorded is unknown: {'; '.join(self.unknown)}"
            )
        else:
            text = "how many messages were recorded (and lost) is unknown: " + "; ".join(
                self.unknown
            )
        if self.lost_before_reindex:
            text += f"; {self.lost_before_reindex} of them lost before `feeder reindex`"
        return text

    def by_topic_text(self, limit: int = _TOPICS_NAMED) -> str:
        """The topics that lost messages: "/a/imu 20000 of 40000, /a/estimate 400 of 800"."""
        lost = self.lost_topics()
        words = [f"{t.topic} {t.lost} of {t.recorded}" for t in lost[:limit]]
        if len(lost) > limit:
            rest = sum(t.lost for t in lost[limit:])
            words.append(f"{rest} on {len(lost) - limit} more topic(s)")
        return ", ".join(words)

    def problem(self) -> BagProblem | None:
        """The ``lost_messages`` problem when messages were counted lost."""
        if not self.lost:
            return None
        topics = self.by_topic_text()
        return BagProblem(
            "lost_messages",
            None,
            self.describe() + (f"; per topic: {topics}" if topics else ""),
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "recorded": self.recorded,
            "readable": self.readable,
            "lost": self.lost,
            "total_known": self.exact,
            "unknown_because": list(self.unknown),
            "sources": list(self.sources),
            "lost_before_reindex": self.lost_before_reindex,
            "topics": [
                {"name": t.topic, "recorded": t.recorded, "readable": t.readable, "lost": t.lost}
                for t in self.topics
            ],
        }


@dataclass(frozen=True)
class _Listed:
    """The counts metadata.yaml gives (None: it gives none)."""

    total: int | None
    topics: dict[str, int]
    files: dict[str, int]
    lost_before: int
    lost_before_topics: dict[str, int]

    @property
    def any(self) -> bool:
        return self.total is not None or bool(self.topics) or bool(self.files)


def _as_count(value: Any) -> int | None:
    try:
        number = int(value)
    except (TypeError, ValueError):
        return None
    return number if number >= 0 else None


def _listed(metadata: Mapping[str, Any] | None) -> _Listed:
    meta = metadata or {}
    topics: dict[str, int] = {}
    for entry in meta.get("topics_with_message_count") or []:
        try:
            name = str(entry["topic_metadata"]["name"])
            count = _as_count(entry["message_count"])
        except (KeyError, TypeError):
            continue
        if count is not None:
            topics[name] = topics.get(name, 0) + count
    files: dict[str, int] = {}
    for entry in meta.get("files") or []:
        try:
            name = Path(str(entry["path"])).name
            count = _as_count(entry["message_count"])
        except (KeyError, TypeError):
            continue
        if count is not None:
            files[name] = count
    custom = meta.get("custom_data") or {}
    custom = custom if isinstance(custom, Mapping) else {}
    before = _as_count(custom.get(LOST_KEY)) or 0
    try:
        by_topic = json.loads(str(custom.get(LOST_BY_TOPIC_KEY) or "{}"))
        before_topics = {str(k): int(v) for k, v in dict(by_topic).items() if int(v) > 0}
    except (ValueError, TypeError):
        before_topics = {}
    return _Listed(_as_count(meta.get("message_count")), topics, files, before, before_topics)


def _file_total(
    file: FileCount, listed: _Listed, use_listing: bool
) -> tuple[int, bool, str | None]:
    """Recorded messages of one file, whether that is its full count, and why not."""
    floor = file.floor
    listed_count = listed.files.get(file.path.name) if use_listing else None
    recorded = max(floor, listed_count or 0)
    if file.recorded_total is not None or (file.complete and not file.uncounted_chunks):
        return recorded, True, None
    if listed_count is not None and listed_count >= floor:
        return recorded, True, None
    name = file.path.name
    if file.complete:
        why = f"{name} has {file.uncounted_chunks} damaged chunk(s) that nothing counts"
    elif listed_count is None:
        why = f"{name} ends without a summary and metadata.yaml does not count it"
    else:
        why = (
            f"{name} ends without a summary and metadata.yaml lists {listed_count} message(s) "
            f"in it, fewer than the {floor} found (written before the file was finished)"
        )
    return recorded, False, why


def count_loss(
    metadata: Mapping[str, Any] | None,
    files: Sequence[FileCount],
    missing: Sequence[Path] = (),
) -> LossCount:
    """Compare what the bag says was recorded with what ``files`` could read (see the module
    docstring). ``missing``: files metadata.yaml lists that are not there (all their messages
    are lost; metadata.yaml's per-file entry counts them)."""
    listed = _listed(metadata)
    use_listing = metadata is not None
    readable: dict[str, int] = {}
    floor: dict[str, int] = {}
    for file in files:
        for topic, n in file.readable.items():
            readable[topic] = readable.get(topic, 0) + n
        own = dict(file.readable)
        for topic, n in file.lost.items():
            own[topic] = own.get(topic, 0) + n
        for topic, n in (file.recorded or {}).items():
            own[topic] = max(own.get(topic, 0), n)
        for topic, n in own.items():
            floor[topic] = floor.get(topic, 0) + n
    names = sorted({*floor, *listed.topics, *listed.lost_before_topics})
    topics = tuple(
        TopicLoss(
            name,
            max(
                floor.get(name, 0),
                listed.topics.get(name, 0) + listed.lost_before_topics.get(name, 0),
            ),
            readable.get(name, 0),
        )
        for name in names
    )
    file_total = 0
    exact = True
    unknown: list[str] = []
    for file in files:
        count, whole, why = _file_total(file, listed, use_listing)
        file_total += count
        exact = exact and whole
        if why:
            unknown.append(why)
    for path in missing:
        count_listed = listed.files.get(path.name)
        file_total += count_listed or 0
        if count_listed is None:
            exact = False
            unknown.append(f"{path.name} is missing and metadata.yaml does not count its messages")
    listed_total = (listed.total or 0) + listed.lost_before
    recorded = max(file_total, listed_total, sum(t.recorded for t in topics))
    sources = []
    if use_listing and listed.any:
        sources.append("metadata.yaml")
    if any(f.recorded_total is not None for f in files):
        sources.append("the MCAP summaries")
    if any(f.lost for f in files):
        sources.append("the damaged chunks' message indexes")
    return LossCount(
        recorded=recorded,
        readable=sum(readable.values()),
        exact=exact,
        topics=topics,
        sources=tuple(sources),
        unknown=tuple(unknown),
        lost_before_reindex=listed.lost_before,
    )


def lost_custom_data(loss: LossCount) -> dict[str, str]:
    """The metadata.yaml ``custom_data`` entries that keep ``loss`` through a reindex (empty when
    nothing was lost)."""
    if not loss.lost:
        return {}
    by_topic = {t.topic: t.lost for t in loss.lost_topics()}
    return {LOST_KEY: str(loss.lost), LOST_BY_TOPIC_KEY: json.dumps(by_topic, sort_keys=True)}
