"""Vectorised column decoding and the generic decoder against rclpy's deserialize_message.

Many random messages per type, with frame_id (and other string) lengths from 0 to 20 bytes so that
every alignment remainder occurs, NaNs and extreme values, bounded and unbounded sequences.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import BatteryState, Imu, JointState, NavSatFix

from feeder_ros.bag import (
    LOG_TIME,
    Bag,
    BagWriter,
    ColumnPlan,
    UnsupportedLayoutError,
    concat_batches,
    decode_cdr,
    iter_messages,
    read_columns,
)
from feeder_ros.bag.schemas import installed_definitions
from feeder_ros.msg import (
    CarrierState,
    DriveCommand,
    DriveState,
    PartExit,
    PartSensorEvent,
    PartStateArray,
    SpeedStatus,
    VehicleEstimate,
)

INT_RANGES = {
    "int8": (-128, 127),
    "uint8": (0, 255),
    "octet": (0, 255),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}
SPECIAL = [float("nan"), float("inf"), -float("inf"), 0.0, -0.0, 1e-300, 3.4e38]


def _random_scalar(rng: np.random.Generator, kind: str) -> Any:
    if kind in ("float", "double"):
        if rng.random() < 0.15:
            value = SPECIAL[int(rng.integers(len(SPECIAL)))]
            return value if kind == "double" or abs(value) < 1e38 or value != value else 1.0
        return float(rng.normal() * 10.0 ** int(rng.integers(-5, 5)))
    if kind == "boolean":
        return bool(rng.random() < 0.5)
    if kind == "string":
        return "".join(rng.choice(list("ab_/01é"), size=int(rng.integers(0, 21))))
    if kind == "octet":  # rclpy wants bytes of length 1 for `byte` fields
        return bytes([int(rng.integers(0, 256))])
    lo, hi = INT_RANGES[kind]
    return int(rng.integers(lo, hi, endpoint=True, dtype=np.int64 if hi < 2**63 else np.uint64))


def fill_random(msg: Any, rng: np.random.Generator) -> Any:
    """Set every field of an rclpy message to random values (nested messages recursively)."""
    for name, kind in msg.get_fields_and_field_types().items():
        seq = re.fullmatch(r"sequence<(\w+)(?:, \d+)?>", kind)
        fixed = re.fullmatch(r"(\w+)\[(\d+)\]", kind)
        if kind.startswith("sequence<") and "/" in kind:
            continue  # sequences of messages: filled by the caller
        if "/" in kind and not seq and not fixed:
            fill_random(getattr(msg, name), rng)
        elif seq and "/" not in kind:
            setattr(
                msg, name, [_random_scalar(rng, seq[1]) for _ in range(int(rng.integers(0, 6)))]
            )
        elif fixed:
            setattr(msg, name, [_random_scalar(rng, fixed[1]) for _ in range(int(fixed[2]))])
        elif "/" not in kind and "<" not in kind:
            setattr(msg, name, _random_scalar(rng, kind.split("<=")[0]))
    return msg


def _attr(msg: Any, path: str) -> Any:
    for part in re.split(r"\.", path):
        match = re.fullmatch(r"(\w+)\[(\d+)\]", part)
        msg = getattr(msg, match[1])[int(match[2])] if match else getattr(msg, part)
    return msg


def assert_value(expected: Any, actual: Any, where: str) -> None:
    if isinstance(expected, bytes) and len(expected) == 1:  # a `byte` field
        assert actual == expected[0], where
    elif isinstance(expected, str):
        assert actual == expected, where
    elif isinstance(expected, float):
        assert (expected != expected and actual != actual) or actual == expected, where
        if expected == 0.0:
            assert np.signbit(expected) == np.signbit(actual), where
    elif isinstance(expected, bool | int):
        assert actual == expected, where
    else:
        np.testing.assert_array_equal(np.asarray(actual), np.asarray(expected), err_msg=where)


COLUMN_TYPES = [
    ("sensor_msgs/msg/Imu", Imu),
    ("sensor_msgs/msg/NavSatFix", NavSatFix),
    ("sensor_msgs/msg/BatteryState", BatteryState),
    ("feeder_ros/msg/CarrierState", CarrierState),
    ("feeder_ros/msg/VehicleEstimate", VehicleEstimate),
    ("feeder_ros/msg/DriveCommand", DriveCommand),
    ("feeder_ros/msg/DriveState", DriveState),
    ("feeder_ros/msg/SpeedStatus", SpeedStatus),
    ("feeder_ros/msg/PartSensorEvent", PartSensorEvent),
    ("feeder_ros/msg/PartExit", PartExit),
]


def packed(
    datas: list[bytes], rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The messages laid into one buffer with random gaps (as in a chunk), and their bounds."""
    parts: list[bytes] = []
    starts, ends = [], []
    pos = 0
    for data in datas:
        gap = bytes(rng.integers(0, 256, size=int(rng.integers(0, 40)), dtype=np.uint8))
        parts += [gap, data]
        pos += len(gap)
        starts.append(pos)
        pos += len(data)
        ends.append(pos)
    buf = np.frombuffer(b"".join(parts), np.uint8)
    return buf, np.array(starts, dtype=np.int64), np.array(ends, dtype=np.int64)


@pytest.mark.parametrize(("type_name", "cls"), COLUMN_TYPES)
def test_column_decode_equals_rclpy(type_name: str, cls: Any) -> None:
    rng = np.random.default_rng(abs(hash(type_name)) % 2**32)
    msgs = [fill_random(cls(), rng) for _ in range(400)]
    datas = [bytes(serialize_message(m)) for m in msgs]
    buf, starts, ends = packed(datas, rng)
    plan = ColumnPlan(installed_definitions(type_name), type_name)
    cols, ok = plan.decode(buf, starts, ends, plan.select(None))
    assert ok.all()
    assert set(cols) == set(plan.columns)
    for i, data in enumerate(datas):
        expected = deserialize_message(data, cls)
        for name, col in cols.items():
            value = col[i]
            value = value.item() if isinstance(value, np.generic) else value
            assert_value(_attr(expected, name), value, f"{type_name} {name} [{i}]")


@pytest.mark.parametrize(
    ("type_name", "cls"), [*COLUMN_TYPES, ("feeder_ros/msg/PartStateArray", PartStateArray)]
)
def test_generic_decode_equals_rclpy(type_name: str, cls: Any) -> None:
    rng = np.random.default_rng(7)
    defs = installed_definitions(type_name)
    for _ in range(60):
        msg = fill_random(cls(), rng)
        if cls is PartStateArray:
            from feeder_ros.msg import PartState

            msg.parts = [fill_random(PartState(), rng) for _ in range(int(rng.integers(0, 4)))]
        data = bytes(serialize_message(msg))
        expected = deserialize_message(data, cls)
        _compare_tree(expected, decode_cdr(data, defs, type_name), type_name)


def _compare_tree(expected: Any, decoded: Any, where: str) -> None:
    if hasattr(expected, "get_fields_and_field_types"):
        assert set(decoded) == set(expected.get_fields_and_field_types()), where
        for name in decoded:
            _compare_tree(getattr(expected, name), decoded[name], f"{where}.{name}")
    elif (
        isinstance(expected, list)
        and expected
        and hasattr(expected[0], "get_fields_and_field_types")
    ):
        assert len(decoded) == len(expected), where
        for i, (e, d) in enumerate(zip(expected, decoded, strict=True)):
            _compare_tree(e, d, f"{where}[{i}]")
    else:
        assert_value(expected, decoded, where)


def _fill_parts(msg: Any, rng: np.random.Generator) -> Any:
    from diagnostic_msgs.msg import KeyValue

    from feeder_ros.msg import PartState

    if isinstance(msg, PartStateArray):
        msg.parts = [fill_random(PartState(), rng) for _ in range(int(rng.integers(0, 7)))]
    elif isinstance(msg, DiagnosticStatus):
        msg.values = [fill_random(KeyValue(), rng) for _ in range(int(rng.integers(0, 4)))]
    elif isinstance(msg, JointState):
        k = int(rng.integers(0, 5))
        msg.name = [_random_scalar(rng, "string") for _ in range(k)]
        msg.position = [_random_scalar(rng, "double") for _ in range(k)]
    return msg


RAGGED_TYPES = [
    ("feeder_ros/msg/PartStateArray", PartStateArray, "parts"),
    ("diagnostic_msgs/msg/DiagnosticStatus", DiagnosticStatus, "values"),
    ("sensor_msgs/msg/JointState", JointState, "name"),
]


@pytest.mark.parametrize(("type_name", "cls", "seq"), RAGGED_TYPES)
def test_ragged_columns_equal_rclpy(type_name: str, cls: Any, seq: str) -> None:
    rng = np.random.default_rng(11)
    msgs = [_fill_parts(fill_random(cls(), rng), rng) for _ in range(300)]
    datas = [bytes(serialize_message(m)) for m in msgs]
    buf, starts, ends = packed(datas, rng)
    plan = ColumnPlan(installed_definitions(type_name), type_name)
    cols, ok = plan.decode(buf, starts, ends, plan.select(None))
    assert ok.all()
    counts = cols[f"{seq}._count"]
    expected = [deserialize_message(d, cls) for d in datas]
    np.testing.assert_array_equal(counts, [len(getattr(e, seq)) for e in expected])
    elements = [x for e in expected for x in getattr(e, seq)]
    ragged = [c for c in cols if c in plan.ragged]
    assert ragged
    for name in ragged:
        assert len(cols[name]) == len(elements) == counts.sum()
        sub = name[len(seq) + 1 :]
        for i, element in enumerate(elements):
            value = cols[name][i]
            value = value.item() if isinstance(value, np.generic) else value
            assert_value(_attr(element, sub) if sub else element, value, f"{name}[{i}]")
    for name, col in cols.items():  # the per-message columns still have one row per message
        if name not in plan.ragged:
            assert len(col) == len(datas), name


def test_ragged_selection_brings_the_count() -> None:
    plan = ColumnPlan(
        installed_definitions("feeder_ros/msg/PartStateArray"), "feeder_ros/msg/PartStateArray"
    )
    assert plan.select(["parts.position_m"]) == {"parts.position_m", "parts._count"}
    assert plan.select(["parts._count"]) == {"parts._count"}


def test_nested_sequences_are_rejected_for_columns() -> None:
    with pytest.raises(UnsupportedLayoutError, match=r"status\.values.*inside a sequence"):
        ColumnPlan(
            installed_definitions("diagnostic_msgs/msg/DiagnosticArray"),
            "diagnostic_msgs/msg/DiagnosticArray",
        )
    rng = np.random.default_rng(3)
    msg = DiagnosticArray(status=[_fill_parts(fill_random(DiagnosticStatus(), rng), rng)])
    data = bytes(serialize_message(msg))
    defs = installed_definitions("diagnostic_msgs/DiagnosticArray")
    decoded = decode_cdr(data, defs, "diagnostic_msgs/DiagnosticArray")
    _compare_tree(deserialize_message(data, DiagnosticArray), decoded, "DiagnosticArray")
    assert decoded["status"][0]["level"] == msg.status[0].level[0]


def test_malformed_ragged_message_is_dropped_consistently(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    msgs = [_fill_parts(fill_random(PartStateArray(), rng), rng) for _ in range(40)]
    datas = [bytes(serialize_message(m)) for m in msgs]
    path = tmp_path / "parts"
    with BagWriter(path) as writer:
        writer.add_topic("/parts", "feeder_ros/msg/PartStateArray")
        for i, data in enumerate(datas):
            writer.write("/parts", data[:-6] if i == 7 else data, i)
    bag = Bag(path, warn=False)
    cols = concat_batches(read_columns(bag, "feeder_ros/PartStateArray"))
    keep = [m for i, m in enumerate(msgs) if i != 7]
    np.testing.assert_array_equal(cols["parts._count"], [len(m.parts) for m in keep])
    np.testing.assert_array_equal(cols["parts.part_id"], [p.part_id for m in keep for p in m.parts])
    assert [p.kind for p in bag.problems] == ["malformed_message"]


def test_big_endian_cdr(tmp_path: Path) -> None:
    schema = "uint8 a\nfloat64 b\nstring c\nint16[2] d\nfloat32[] e\n"
    path = tmp_path / "be"
    rows = []
    with BagWriter(path) as writer:
        writer.add_topic("/be", "acme_msgs/msg/Be", schema_text=schema, type_hash="")
        for i in range(12):
            c = "x" * (i % 5)
            e = [float(k) for k in range(i % 3)]
            for order, kind in ((">", 0), ("<", 1)):
                body = struct.pack(f"{order}B7xd", i, i / 4)
                body += struct.pack(f"{order}I", len(c) + 1) + c.encode() + b"\x00"
                body += b"\x00" * (-len(body) % 2) + struct.pack(f"{order}hh", -i, i)
                body += b"\x00" * (-len(body) % 4) + struct.pack(f"{order}I", len(e))
                body += struct.pack(f"{order}{len(e)}f", *e)
                writer.write("/be", bytes([0, kind, 0, 0]) + body, 1000 + 2 * i + kind)
                rows.append((i, c, e))
    batches = list(read_columns(path, "acme_msgs/msg/Be"))
    cols = concat_batches(batches)
    order = np.argsort(cols[LOG_TIME])
    assert [int(v) for v in cols["a"][order]] == [r[0] for r in rows]
    np.testing.assert_array_equal(cols["b"][order], [r[0] / 4 for r in rows])
    assert list(cols["c"][order]) == [r[1] for r in rows]
    np.testing.assert_array_equal(cols["d"][order], [[-r[0], r[0]] for r in rows])
    for got, row in zip(cols["e"][order], rows, strict=True):
        np.testing.assert_array_equal(got, row[2])
    decoded = [m.decode() for m in iter_messages(path)]
    assert [d["c"] for d in decoded] == [r[1] for r in rows]
    assert [list(d["d"]) for d in decoded] == [[-r[0], r[0]] for r in rows]


def test_unwanted_chunks_are_not_decompressed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "skip"
    imu = bytes(serialize_message(Imu()))
    state = bytes(serialize_message(CarrierState()))
    with BagWriter(path, chunk_size=2000) as writer:
        writer.add_topic("/other/state", "feeder_ros/msg/CarrierState")
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
        for i in range(300):
            writer.write("/other/state", state, i)
        for i in range(300, 330):
            writer.write("/imu", imu, i)
    import zstandard

    calls = []
    real = zstandard.ZstdDecompressor

    class Counting:
        def __init__(self) -> None:
            self.real = real()

        def decompress(self, *args: Any, **kwargs: Any) -> bytes:
            calls.append(1)
            return bytes(self.real.decompress(*args, **kwargs))

    monkeypatch.setattr("feeder_ros.bag.scan.zstandard.ZstdDecompressor", Counting)
    batches = list(read_columns(path, "sensor_msgs/Imu", ["header"]))
    np.testing.assert_array_equal(concat_batches(batches)[LOG_TIME], np.arange(300, 330))
    with (path / "skip_0.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
    assert len(summary.chunk_indexes) > 20
    assert len(calls) == len(batches) < 8  # only the chunks that hold /imu messages
