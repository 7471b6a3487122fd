"""MCAP record opcodes and magic (https://mcap.dev/spec) for the damage scan and reindex, which
read files record by record where ``mcap``'s reader stops at the first damage. (Plain ints, not
``mcap.opcode.Opcode``: the scan compares one per record.) Files are written by ``mcap``'s writer.
"""

from __future__ import annotations

__all__ = ["MAGIC", "Op"]

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
