"""Exceptions and problem records of the bag core; each builds its message from the values involved.

Errors (``BagError`` and subclasses) stop an operation. Problems (``BagProblem``) are findings that
the reader records while it carries on with the data it can still use (a corrupt chunk is skipped, a
file that ends without a footer is read up to its last complete chunk); they are collected in
``Bag.problems`` and also issued as ``BagWarning`` warnings.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "DATA_LOSS_KINDS",
    "BagError",
    "BagProblem",
    "BagWarning",
    "CorruptRecordError",
    "MessageDefinitionError",
    "MissingBagError",
    "UnknownTypeError",
    "UnsupportedLayoutError",
    "WriterStateError",
]


class BagError(Exception):
    """Base class of every error raised by ``feeder_ros.bag``."""


class BagWarning(UserWarning):
    """A problem the reader worked around (see ``BagProblem``)."""


class MissingBagError(BagError, FileNotFoundError):
    """The bag path holds neither a bag directory nor an MCAP file."""

    def __init__(self, path: Path | str, reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"no bag at {self.path}: {reason}")


class CorruptRecordError(BagError):
    """An MCAP record that cannot be parsed."""

    def __init__(self, file: Path | str, offset: int, reason: str) -> None:
        self.file = Path(file)
        self.offset = offset
        self.reason = reason
        super().__init__(f"{self.file} at byte {offset}: {reason}")


class MessageDefinitionError(BagError):
    """A ros2msg definition that cannot be parsed or resolved."""

    def __init__(self, type_name: str, reason: str) -> None:
        self.type_name = type_name
        self.reason = reason
        super().__init__(f"message definition of {type_name!r}: {reason}")


class UnknownTypeError(MessageDefinitionError):
    """A message type whose .msg file is not installed (not found on the search path)."""

    def __init__(self, type_name: str, searched: list[Path]) -> None:
        self.searched = list(searched)
        where = ", ".join(str(p) for p in self.searched) or "(empty search path)"
        super().__init__(type_name, f"no .msg file found; searched {where}")


class UnsupportedLayoutError(BagError):
    """A message type the column decoder cannot handle (use ``iter_messages`` instead)."""

    def __init__(self, type_name: str, field: str, reason: str) -> None:
        self.type_name = type_name
        self.field = field
        self.reason = reason
        super().__init__(
            f"cannot decode {type_name} into columns: field {field!r} {reason}; "
            "use iter_messages() and decode each message instead"
        )


class WriterStateError(BagError):
    """A BagWriter call that does not fit the writer's state (closed, unknown topic, ...)."""

    def __init__(self, path: Path | str, reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"bag writer {self.path}: {reason}")


#: Problem kinds that mean recorded messages could not be read: what is analysed of such a bag
#: (message counts, exits, feed rates) comes out short. A file cut short counts too when it is not
#: the bag's last file (``Bag.lost_data``).
DATA_LOSS_KINDS = frozenset(
    {
        "corrupt_chunk",  # a chunk skipped
        "corrupt_record",  # bytes skipped over (a damaged record header or record)
        "missing_file",  # a split file listed in metadata.yaml is not there
        "unreadable",  # a file that cannot be opened
        "not_mcap",  # a file in the bag that is not MCAP (zero bytes, overwritten, ...)
        "malformed_message",  # messages that end before their last field, dropped
        "unsupported_encoding",  # messages without a plain CDR header, skipped
        "unknown_channel",  # messages of a channel never defined (its record lost)
        "cut_chunk",  # the file ends inside a chunk (or message): its messages lost
        "lost_messages",  # fewer messages readable than metadata.yaml or the summaries count
    }
)


@dataclass(frozen=True)
class BagProblem:
    """One finding of the reader: what, where (file, byte offset, topic) and what was done."""

    kind: str  # "cut_short", "corrupt_chunk", "lost_messages", "missing_metadata", ...
    file: Path | None
    detail: str
    offset: int | None = None
    topic: str | None = None
    #: a skipped chunk: the recording time its messages spanned (log times, from its header) [ns];
    #: None when unknown (its header unreadable)
    lost_ns: int | None = None

    def __str__(self) -> str:
        where = [str(self.file)] if self.file is not None else []
        if self.offset is not None:
            where.append(f"byte {self.offset}")
        if self.topic is not None:
            where.append(f"topic {self.topic}")
        prefix = f"{', '.join(where)}: " if where else ""
        lost = f" ({self.lost_ns * 1e-9:.4g} s of recording lost)" if self.lost_ns else ""
        return f"[{self.kind}] {prefix}{self.detail}{lost}"
