"""CDR decoding: vectorised column decoding of many messages at once, and a generic per-message
decoder.

ROS 2 serialises messages as XCDR1 (plain CDR): a 4-byte encapsulation header (``00 01`` little
endian, ``00 00`` big endian, then two option bytes), then the fields in order, each primitive
aligned to its own size (at most 8) relative to the first byte after the header. Strings are a
``uint32`` length (including the terminating NUL) and the bytes; sequences a ``uint32`` count and
the elements.

Column decoding (``ColumnPlan``) flattens a message type into runs of primitive fields, strings and
primitive sequences. Every message of a batch has its own read position (one ``int64`` per message).
A run of primitives starts at an aligned position whose remainder modulo 8 fixes the padding inside
the run, so the messages of a batch are grouped by that remainder (nearly always a single group) and
each group is read with ONE fancy-indexing gather through a structured dtype laid over the chunk
buffer with a one-byte stride. A ``std_msgs/Header`` costs one string op (the frame_id length moves
the positions); everything after it is again one gather.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from feeder_ros.bag.errors import UnsupportedLayoutError
from feeder_ros.bag.msgdef import PRIMITIVE_SIZES, Field, MsgDefs, normalize_type

__all__ = ["ColumnPlan", "decode_cdr", "encapsulation_order"]

Columns = dict[str, npt.NDArray[Any]]
IntArray = npt.NDArray[np.int64]

_NP_CODES: dict[str, str] = {
    "bool": "?",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}
_STRUCT_CODES: dict[str, str] = {
    "bool": "?",
    "byte": "B",
    "char": "B",
    "int8": "b",
    "uint8": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float32": "f",
    "float64": "d",
}
EMPTY_FIELD = "structure_needs_at_least_one_member"


def encapsulation_order(kind: int) -> str | None:
    """Byte order ('<' or '>') of a plain-CDR encapsulation id (byte 1 of the header), else None."""
    return {1: "<", 0: ">"}.get(kind)


# ----------------------------------------------------------------------------------------- plan


@dataclass(frozen=True)
class _Prim:
    name: str
    type: str
    count: int  # 0: scalar, N: fixed array of N

    @property
    def size(self) -> int:
        return PRIMITIVE_SIZES[self.type]


@dataclass(frozen=True)
class _Run:
    fields: tuple[_Prim, ...]


@dataclass(frozen=True)
class _Str:
    name: str


@dataclass(frozen=True)
class _Seq:
    name: str
    type: str


@dataclass(frozen=True)
class _SeqMsg:
    """A sequence of messages (or of strings): flat columns over all elements, plus a count."""

    name: str
    ops: tuple[_Run | _Str | _Seq, ...]  # element ops; names are full column names
    min_size: int  # fewest bytes an element can take (bounds the count of a corrupt message)


_Op = _Run | _Str | _Seq | _SeqMsg
_Item = _Prim | _Str | _Seq | _SeqMsg
COUNT_SUFFIX = "._count"


def _fields_of(defs: MsgDefs, type_name: str) -> tuple[Field, ...]:
    fields = defs[type_name]
    return fields if fields else (Field(EMPTY_FIELD, "uint8"),)


def _merge_runs(items: list[_Item]) -> tuple[_Op, ...]:
    ops: list[_Op] = []
    for item in items:
        if isinstance(item, _Prim):
            if ops and isinstance(ops[-1], _Run):
                ops[-1] = _Run((*ops[-1].fields, item))
            else:
                ops.append(_Run((item,)))
        else:
            ops.append(item)
    return tuple(ops)


def _min_size(items: list[_Item]) -> int:
    total = 0
    for item in items:
        total += item.size * max(item.count, 1) if isinstance(item, _Prim) else 4
    return max(total, 1)


def _flatten(
    defs: MsgDefs, top: str, type_name: str, prefix: str, out: list[_Item], nested: bool
) -> None:
    for f in _fields_of(defs, type_name):
        name = prefix + f.name
        if f.array == "seq" and nested and not f.is_primitive:
            raise UnsupportedLayoutError(top, name, "is a sequence inside a sequence of messages")
        if f.is_primitive:
            if f.array == "seq":
                out.append(_Seq(name, f.type))
            else:
                out.append(_Prim(name, f.type, f.count if f.array == "fixed" else 0))
        elif f.is_string:
            if f.type == "wstring":
                raise UnsupportedLayoutError(top, name, "is a wstring")
            if f.array == "seq":
                out.append(_SeqMsg(name, (_Str(name),), 4))
            elif f.array == "fixed":
                out.extend(_Str(f"{name}[{i}]") for i in range(f.count))
            else:
                out.append(_Str(name))
        elif f.array == "seq":
            element: list[_Item] = []
            _flatten(defs, top, f.type, name + ".", element, nested=True)
            ops = _merge_runs(element)
            out.append(
                _SeqMsg(
                    name, tuple(op for op in ops if not isinstance(op, _SeqMsg)), _min_size(element)
                )
            )
        elif f.array == "fixed":
            for i in range(f.count):
                _flatten(defs, top, f.type, f"{name}[{i}].", out, nested)
        else:
            _flatten(defs, top, f.type, name + ".", out, nested)


def _align(pos: IntArray, alignment: int) -> IntArray:
    return (pos + (alignment - 1)) & ~(alignment - 1)


def _op_columns(op: _Op) -> list[str]:
    if isinstance(op, _Run):
        return [f.name for f in op.fields]
    if isinstance(op, _SeqMsg):
        return [c for sub in op.ops for c in _op_columns(sub)] + [op.name + COUNT_SUFFIX]
    return [op.name]


class ColumnPlan:
    """Column decoder of one message type.

    Columns are named by the dotted field path (``header.stamp.sec``, ``orientation.x``; elements
    of fixed arrays of messages as ``poses[2].x``); a fixed array of primitives is one 2-D column, a
    sequence of primitives an object column of arrays. A sequence of messages (or strings) gives
    ragged columns: ``parts.position_m`` holds the elements of all messages of the batch one after
    the other, and ``parts._count`` (one per message) how many belong to each message. Raises
    ``UnsupportedLayoutError`` for wstrings and sequences nested in sequences of messages (use the
    generic decoder).
    """

    def __init__(self, defs: MsgDefs, type_name: str) -> None:
        self.type_name = normalize_type(type_name)
        flat: list[_Item] = []
        _flatten(defs, self.type_name, self.type_name, "", flat, nested=False)
        self.ops: tuple[_Op, ...] = _merge_runs(flat)
        self.columns: tuple[str, ...] = tuple(c for op in self.ops for c in _op_columns(op))
        # ragged column -> its count column
        self.ragged: dict[str, str] = {
            c: op.name + COUNT_SUFFIX
            for op in self.ops
            if isinstance(op, _SeqMsg)
            for sub in op.ops
            for c in _op_columns(sub)
        }
        self._empty: dict[str, np.dtype[Any]] = {}
        for op in self.ops:
            if isinstance(op, _SeqMsg):
                for sub in op.ops:
                    if isinstance(sub, _Run):
                        for f in sub.fields:
                            code = _NP_CODES[f.type]
                            self._empty[f.name] = np.dtype((code, (f.count,)) if f.count else code)
                    elif isinstance(sub, _Str):
                        self._empty[sub.name] = np.dtype("U1")
                    else:
                        self._empty[sub.name] = np.dtype(object)
        self._layouts: dict[tuple[_Run, int, str], tuple[np.dtype[Any], int]] = {}

    def select(self, fields: Collection[str] | None) -> frozenset[str]:
        """Column names selected by ``fields`` (a name selects itself and every column below it;
        a ragged column brings its count column)."""
        if fields is None:
            return frozenset(self.columns)
        chosen: set[str] = set()
        for want in fields:
            hits = [c for c in self.columns if c == want or c.startswith((want + ".", want + "["))]
            if not hits:
                raise KeyError(f"{self.type_name} has no field {want!r}; fields: {self.columns}")
            chosen.update(hits)
        chosen.update(self.ragged[c] for c in list(chosen) if c in self.ragged)
        return frozenset(chosen)

    def _layout(self, run: _Run, residual: int, order: str) -> tuple[np.dtype[Any], int]:
        key = (run, residual, order)
        cached = self._layouts.get(key)
        if cached is not None:
            return cached
        names: list[str] = []
        formats: list[Any] = []
        offsets: list[int] = []
        cur = residual
        for f in run.fields:
            size = f.size
            cur = (cur + size - 1) & ~(size - 1)
            names.append(f.name)
            code = order + _NP_CODES[f.type] if size > 1 else _NP_CODES[f.type]
            formats.append((code, (f.count,)) if f.count else code)
            offsets.append(cur - residual)
            cur += size * max(f.count, 1)
        length = cur - residual
        dtype = np.dtype(
            {"names": names, "formats": formats, "offsets": offsets, "itemsize": length}
        )
        self._layouts[key] = (dtype, length)
        return dtype, length

    def decode(
        self,
        buf: npt.NDArray[np.uint8],
        starts: IntArray,
        ends: IntArray,
        wanted: frozenset[str],
        order: str = "<",
    ) -> tuple[Columns, npt.NDArray[np.bool_]]:
        """Decode the messages whose CDR payloads (header included) are ``buf[starts[i]:ends[i]]``.

        All messages must have byte order ``order``. Returns the wanted columns and a mask of the
        messages that decoded within their bounds (rows of the others hold garbage).
        """
        origin = starts + 4
        limit = ends - origin
        valid = limit >= 0
        pos = np.zeros(len(starts), dtype=np.int64)
        out, _, valid = self._run_ops(self.ops, buf, origin, pos, limit, valid, wanted, order)
        return out, valid

    def _run_ops(
        self,
        ops: tuple[_Op, ...],
        buf: npt.NDArray[np.uint8],
        origin: IntArray,
        pos: IntArray,
        limit: IntArray,
        valid: npt.NDArray[np.bool_],
        wanted: frozenset[str],
        order: str,
    ) -> tuple[Columns, IntArray, npt.NDArray[np.bool_]]:
        n = len(origin)
        out: Columns = {}
        size = len(buf)
        for op in ops:
            if isinstance(op, _Run):
                pos = _align(pos, op.fields[0].size)
                residuals = pos & 7
                lo, hi = int(residuals.min(initial=0)), int(residuals.max(initial=0))
                groups = [lo] if lo == hi else [int(r) for r in np.unique(residuals)]
                for r in groups:
                    dtype, length = self._layout(op, r, order)
                    sel: slice | IntArray = (
                        slice(None) if lo == hi else np.flatnonzero(residuals == r)
                    )
                    gpos = pos[sel]
                    ok = valid[sel] & (gpos + length <= limit[sel])
                    valid[sel] = ok
                    at = np.where(ok, origin[sel] + gpos, 0)
                    if size < length:
                        valid[sel] = False
                        continue
                    names = [f.name for f in op.fields if f.name in wanted]
                    if names:
                        rec, is_view = _records(buf, at, dtype, length)
                        for name in names:
                            if lo == hi:
                                out[name] = rec[name].copy() if is_view else rec[name]
                            else:
                                col = out.get(name)
                                if col is None:
                                    sub = rec.dtype[name]
                                    col = np.empty((n, *sub.shape), sub.base)
                                    out[name] = col
                                col[sel] = rec[name]
                    pos[sel] = gpos + length
            elif isinstance(op, _Str):
                pos = _align(pos, 4)
                count, valid = _read_u32(buf, origin, pos, limit, valid, order)
                if op.name in wanted:
                    out[op.name] = _strings(buf, origin + pos + 4, count, valid)
                pos = pos + 4 + count
                valid &= pos <= limit
            elif isinstance(op, _Seq):
                pos = _align(pos, 4)
                count, valid = _read_u32(buf, origin, pos, limit, valid, order)
                esize = PRIMITIVE_SIZES[op.type]
                data_pos = _align(pos + 4, esize)
                new_pos = np.where(count > 0, data_pos + count * esize, pos + 4)
                valid &= new_pos <= limit
                if op.name in wanted:
                    out[op.name] = _sequences(buf, origin + data_pos, count, valid, op.type, order)
                pos = new_pos
            else:
                pos, valid = self._seq_msg(op, buf, origin, pos, limit, valid, wanted, order, out)
        return out, pos, valid

    def _seq_msg(
        self,
        op: _SeqMsg,
        buf: npt.NDArray[np.uint8],
        origin: IntArray,
        pos: IntArray,
        limit: IntArray,
        valid: npt.NDArray[np.bool_],
        wanted: frozenset[str],
        order: str,
        out: Columns,
    ) -> tuple[IntArray, npt.NDArray[np.bool_]]:
        """Elements of a sequence of messages, element index by element index (all messages at
        once for each index), scattered into flat columns in message order."""
        pos = _align(pos, 4)
        count, valid = _read_u32(buf, origin, pos, limit, valid, order)
        pos = pos + 4
        valid &= count * op.min_size <= limit - pos
        count = np.where(valid, count, 0)
        first = np.cumsum(count) - count
        total = int(count.sum())
        flat: Columns = {}
        for k in range(int(count.max(initial=0))):
            act = np.flatnonzero(count > k)
            cols, sub_pos, sub_valid = self._run_ops(
                op.ops, buf, origin[act], pos[act], limit[act], valid[act], wanted, order
            )
            pos[act] = sub_pos
            valid[act] = sub_valid
            where = first[act] + k
            for name, col in cols.items():
                target = flat.get(name)
                if target is None or (target.dtype.kind == "U" and col.dtype > target.dtype):
                    grown = np.empty((total, *col.shape[1:]), col.dtype)
                    if target is not None:
                        grown[...] = target
                    flat[name] = target = grown
                target[where] = col
        for sub in op.ops:
            for name in _op_columns(sub):
                if name in wanted and name not in flat:
                    flat[name] = np.empty(0, self._empty[name])
        out.update(flat)
        if op.name + COUNT_SUFFIX in wanted:
            out[op.name + COUNT_SUFFIX] = count
        return pos, valid


def _read_u32(
    buf: npt.NDArray[np.uint8],
    origin: IntArray,
    pos: IntArray,
    limit: IntArray,
    valid: npt.NDArray[np.bool_],
    order: str,
) -> tuple[IntArray, npt.NDArray[np.bool_]]:
    valid = valid & (pos + 4 <= limit)
    at = np.where(valid, origin + pos, 0)
    if len(buf) < 4:
        return np.zeros(len(pos), dtype=np.int64), np.zeros(len(pos), dtype=np.bool_)
    view = np.ndarray((len(buf) - 3,), dtype=order + "u4", buffer=buf, strides=(1,))
    count = np.where(valid, view[at], 0).astype(np.int64)
    return count, valid


def _records(
    buf: npt.NDArray[np.uint8], at: IntArray, dtype: np.dtype[Any], length: int
) -> tuple[npt.NDArray[Any], bool]:
    """Records of ``dtype`` starting at the byte offsets ``at``: one fancy-indexing gather through a
    one-byte-stride view (a copy), or a strided view of ``buf`` when the offsets are evenly spaced
    (the flag is True; copy what you keep)."""
    n = len(at)
    if n > 1:
        stride = int(at[1] - at[0])
        evenly = stride >= length and int(at[-1]) == int(at[0]) + stride * (n - 1)
        if evenly and bool(np.all(np.diff(at) == stride)):
            view = np.ndarray((n,), dtype, buffer=buf, offset=int(at[0]), strides=(stride,))
            return view, True
    full = np.ndarray((len(buf) - length + 1,), dtype=dtype, buffer=buf, strides=(1,))
    return full[at], False


def _strings(
    buf: npt.NDArray[np.uint8], at: IntArray, count: IntArray, valid: npt.NDArray[np.bool_]
) -> npt.NDArray[np.str_]:
    """Strings of ``count`` bytes (NUL included) at ``at``, decoded as UTF-8, grouped by length."""
    nbytes = np.where(valid, np.maximum(count - 1, 0), 0)
    nbytes = np.minimum(nbytes, np.maximum(len(buf) - at, 0))
    longest = int(nbytes.max(initial=0))
    out = np.full(len(at), "", dtype=f"U{max(longest, 1)}")
    lo = int(nbytes.min(initial=0))
    lengths = [lo] if lo == longest else np.unique(nbytes).tolist()
    for length in lengths:
        if length == 0:
            continue
        sel: slice | IntArray = slice(None) if lo == longest else np.flatnonzero(nbytes == length)
        view = np.ndarray(
            (len(buf) - int(length) + 1,), dtype=f"S{int(length)}", buffer=buf, strides=(1,)
        )
        raw = view[at[sel]]
        if len(raw) > 1 and bool(np.all(raw == raw[0])):
            out[sel] = raw[0].decode("utf-8", "replace")
            continue
        try:
            out[sel] = raw.astype(f"U{int(length)}")  # ASCII: fast path
        except UnicodeDecodeError:
            out[sel] = np.char.decode(raw, "utf-8", errors="replace")
    return out


def _sequences(
    buf: npt.NDArray[np.uint8],
    at: IntArray,
    count: IntArray,
    valid: npt.NDArray[np.bool_],
    type_name: str,
    order: str,
) -> npt.NDArray[np.object_]:
    dtype = np.dtype((order if PRIMITIVE_SIZES[type_name] > 1 else "") + _NP_CODES[type_name])
    out = np.empty(len(at), dtype=object)
    raw = buf.data
    for i, (start, n, ok) in enumerate(
        zip(at.tolist(), count.tolist(), valid.tolist(), strict=True)
    ):
        out[i] = (
            np.frombuffer(raw, dtype=dtype, count=n, offset=start).copy()
            if ok and n
            else np.empty(0, dtype)
        )
    return out


# ------------------------------------------------------------------------------ generic decoder

_Decoder = Callable[[memoryview, int], tuple[Any, int]]


class _GenericDecoder:
    """Per-message decoder built from the definitions: messages become nested dicts."""

    def __init__(self, defs: MsgDefs, order: str) -> None:
        self.defs = defs
        self.order = order
        self._cache: dict[str, _Decoder] = {}

    def for_type(self, type_name: str) -> _Decoder:
        decoder = self._cache.get(type_name)
        if decoder is None:
            decoder = self._build(type_name)
            self._cache[type_name] = decoder
        return decoder

    def _build(self, type_name: str) -> _Decoder:
        parts = [(f.name, self._field(f)) for f in _fields_of(self.defs, type_name)]

        def decode(buf: memoryview, pos: int) -> tuple[Any, int]:
            result: dict[str, Any] = {}
            for name, part in parts:
                result[name], pos = part(buf, pos)
            return result, pos

        return decode

    def _field(self, f: Field) -> _Decoder:
        order = self.order
        if f.is_primitive:
            size = PRIMITIVE_SIZES[f.type]
            code = struct.Struct(order + _STRUCT_CODES[f.type])
            dtype = np.dtype((order if size > 1 else "") + _NP_CODES[f.type])

            def scalar(buf: memoryview, pos: int) -> tuple[Any, int]:
                pos = _align1(pos, size)
                return code.unpack_from(buf, pos + 4)[0], pos + size

            def array(buf: memoryview, pos: int, count: int) -> tuple[Any, int]:
                if count == 0:
                    return np.empty(0, dtype), pos
                pos = _align1(pos, size)
                end = pos + count * size
                if end + 4 > len(buf):
                    raise ValueError(f"array of {count} {f.type} runs past the message end")
                return np.frombuffer(buf, dtype, count, pos + 4).copy(), end

            elem: _Decoder | None = None
            array_fn: Callable[[memoryview, int, int], tuple[Any, int]] | None = array
            if f.array is None:
                return scalar
        elif f.is_string:
            wide = f.type == "wstring"

            def string(buf: memoryview, pos: int) -> tuple[Any, int]:
                pos = _align1(pos, 4)
                (n,) = struct.unpack_from(order + "I", buf, pos + 4)
                start = pos + 8
                if wide:
                    end = start + 4 * n
                    text = bytes(buf[start:end]).decode(
                        "utf-32-le" if order == "<" else "utf-32-be"
                    )
                else:
                    end = start + n
                    text = bytes(buf[start : end - 1 if n else end]).decode("utf-8", "replace")
                if end + 0 > len(buf):
                    raise ValueError("string runs past the message end")
                return text, end - 4

            elem, array_fn = string, None
            if f.array is None:
                return string
        else:
            elem, array_fn = self.for_type_lazy(f.type), None
            if f.array is None:
                return elem

        def fixed_or_seq(buf: memoryview, pos: int) -> tuple[Any, int]:
            if f.array == "fixed":
                count = f.count
            else:
                pos = _align1(pos, 4)
                (count,) = struct.unpack_from(order + "I", buf, pos + 4)
                pos += 4
            if array_fn is not None:
                return array_fn(buf, pos, count)
            assert elem is not None
            items = []
            for _ in range(count):
                item, pos = elem(buf, pos)
                items.append(item)
            return items, pos

        return fixed_or_seq

    def for_type_lazy(self, type_name: str) -> _Decoder:
        def decode(buf: memoryview, pos: int) -> tuple[Any, int]:
            return self.for_type(type_name)(buf, pos)

        return decode


def _align1(pos: int, alignment: int) -> int:
    return (pos + alignment - 1) & ~(alignment - 1)


_GENERIC: dict[tuple[int, str], _GenericDecoder] = {}


def decode_cdr(data: bytes | memoryview, defs: MsgDefs, type_name: str) -> dict[str, Any]:
    """Decode one CDR message (encapsulation header included) into nested dicts.

    Primitive arrays become numpy arrays, sequences of messages lists of dicts, strings ``str``.
    Raises ``ValueError`` for an unknown encapsulation or a message that ends too early.
    """
    buf = memoryview(data)
    if len(buf) < 4:
        raise ValueError(f"a CDR message needs at least 4 bytes, got {len(buf)}")
    order = encapsulation_order(buf[1])
    if buf[0] != 0 or order is None:
        raise ValueError(f"unsupported CDR encapsulation {bytes(buf[:2]).hex()}")
    key = (id(defs), order)
    decoder = _GENERIC.get(key)
    if decoder is None or decoder.defs is not defs:
        if len(_GENERIC) >= 64:  # a small cache: definitions come and go with bags
            _GENERIC.clear()
        decoder = _GenericDecoder(defs, order)
        _GENERIC[key] = decoder
    try:
        value, _ = decoder.for_type(normalize_type(type_name))(buf, 0)
    except struct.error as err:
        raise ValueError(f"{type_name} message of {len(buf)} bytes ends too early: {err}") from None
    return dict(value)
