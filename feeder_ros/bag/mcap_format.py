"""MCAP record layout shared by the writer and the reader (https://mcap.dev/spec).

Every record is ``opcode:uint8, length:uint64, content``; integers are little endian; a string is a
``uint32`` byte length and UTF-8; a map is a ``uint32`` byte length and its key/value pairs.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping

__all__ = [
    "MAGIC",
    "MESSAGE_HEADER",
    "Op",
    "encode_map",
    "encode_record",
    "encode_str",
    "encode_u16_u64_map",
]

MAGIC = b"\x89MCAP0\r\n"


class Op:
    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


# opcode, record length, channel id, sequence, log time, publish time; the data follows.
MESSAGE_HEADER = struct.Struct("<BQHIQQ")
MESSAGE_FIXED = 22  # content bytes before the data
RECORD_HEADER = struct.Struct("<BQ")


def encode_str(text: str) -> bytes:
    raw = text.encode("utf-8")
    return struct.pack("<I", len(raw)) + raw


def encode_map(values: Mapping[str, str]) -> bytes:
    body = b"".join(encode_str(k) + encode_str(v) for k, v in values.items())
    return struct.pack("<I", len(body)) + body


def encode_u16_u64_map(values: Mapping[int, int]) -> bytes:
    body = b"".join(struct.pack("<HQ", k, v) for k, v in values.items())
    return struct.pack("<I", len(body)) + body


def encode_record(opcode: int, content: bytes) -> bytes:
    return RECORD_HEADER.pack(opcode, len(content)) + content
