"""Bags written by BagWriter, read back by rosbags, by the mcap package and by our reader.

Messages are real ROS 2 messages serialized by rclpy; every count, time range and field is checked.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from sensor_msgs.msg import Imu

from feeder_ros.bag import (
    LOG_TIME,
    PUBLISH_TIME,
    Bag,
    BagWriter,
    bag_info,
    concat_batches,
    iter_messages,
    read_columns,
    ros2msg_schema,
)
from feeder_ros.msg import (
    CarrierState,
    DriveCommand,
    DriveState,
    PartState,
    PartStateArray,
    VehicleEstimate,
)

RNG_SEED = 20261121
T0 = 1_700_000_000_000_000_000


def _stamp(msg: Any, t_ns: int) -> None:
    msg.header.stamp.sec = t_ns // 1_000_000_000
    msg.header.stamp.nanosec = t_ns % 1_000_000_000


def _frame(rng: np.random.Generator) -> str:
    return "".join(rng.choice(list("abcxyz_/0"), size=int(rng.integers(0, 21))))


def _float(rng: np.random.Generator) -> float:
    return (
        float("nan") if rng.random() < 0.05 else float(rng.normal() * 10.0 ** rng.integers(-6, 6))
    )


def make_imu(rng: np.random.Generator, t_ns: int) -> Imu:
    m = Imu()
    _stamp(m, t_ns)
    m.header.frame_id = _frame(rng)
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = (
        _float(rng) for _ in range(4)
    )
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = (
        _float(rng) for _ in range(3)
    )
    m.linear_acceleration.x = _float(rng)
    m.linear_acceleration.y = _float(rng)
    m.linear_acceleration.z = _float(rng)
    m.orientation_covariance = [_float(rng) for _ in range(9)]
    m.angular_velocity_covariance = [_float(rng) for _ in range(9)]
    m.linear_acceleration_covariance = [_float(rng) for _ in range(9)]
    return m


def make_carrier(rng: np.random.Generator, t_ns: int) -> CarrierState:
    m = CarrierState()
    _stamp(m, t_ns)
    m.header.frame_id = _frame(rng)
    m.displacement_m = _float(rng)
    m.velocity_mps = _float(rng)
    m.acceleration_mps2 = _float(rng)
    m.stiffness_branch = int(rng.choice([-1, 1]))
    m.drive_frequency_hz = _float(rng)
    m.drive_amplitude_n = _float(rng)
    m.drive_force_n = _float(rng)
    return m


def make_estimate(rng: np.random.Generator, t_ns: int) -> VehicleEstimate:
    m = VehicleEstimate()
    _stamp(m, t_ns)
    m.header.frame_id = _frame(rng)
    for name in (
        "carrier_velocity_mps",
        "part_velocity_mps",
        "part_velocity_confidence",
        "phase_confidence",
        "advance_per_cycle_m",
        "advance_per_cycle_confidence",
        "slip_fraction",
        "slip_fraction_confidence",
        "mean_speed_mps",
        "mean_speed_confidence",
        "window_s",
    ):
        setattr(m, name, _float(rng))
    m.phase = int(rng.integers(0, 3))
    m.status = int(rng.integers(0, 7))
    m.status_message = "ünïcode ok" if rng.random() < 0.3 else _frame(rng)
    return m


def make_command(rng: np.random.Generator, t_ns: int) -> DriveCommand:
    m = DriveCommand()
    _stamp(m, t_ns)
    m.header.frame_id = _frame(rng)
    m.enabled = bool(rng.random() < 0.5)
    m.frequency_hz = _float(rng)
    m.amplitude_percent = _float(rng)
    m.amplitude_n = _float(rng)
    m.ramp_time_s = _float(rng)
    return m


def make_drive_state(rng: np.random.Generator, t_ns: int) -> DriveState:
    m = DriveState()
    _stamp(m, t_ns)
    m.header.frame_id = _frame(rng)
    m.state = int(rng.integers(0, 5))
    m.frequency_hz = _float(rng)
    m.speed_mode = bool(rng.random() < 0.5)
    m.backend = _frame(rng)
    m.fault_reason = _frame(rng)
    return m


def make_parts(rng: np.random.Generator, t_ns: int) -> PartStateArray:
    m = PartStateArray()
    _stamp(m, t_ns)
    m.header.frame_id = _frame(rng)
    for i in range(int(rng.integers(0, 5))):
        p = PartState()
        p.part_id = i
        p.position_m = _float(rng)
        p.velocity_mps = _float(rng)
        p.phase = int(rng.integers(0, 3))
        p.on_track = bool(rng.random() < 0.5)
        m.parts.append(p)
    return m


MAKERS = {
    "sensor_msgs/msg/Imu": make_imu,
    "feeder_ros/msg/CarrierState": make_carrier,
    "feeder_ros/msg/VehicleEstimate": make_estimate,
    "feeder_ros/msg/DriveCommand": make_command,
    "feeder_ros/msg/DriveState": make_drive_state,
    "feeder_ros/msg/PartStateArray": make_parts,
}
# Namespaced/remapped names on purpose: the reader must find feeder topics by type.
TOPICS = {
    "/cell1/imu/data_raw": "sensor_msgs/msg/Imu",
    "/cell1/feeder/carrier_state": "feeder_ros/msg/CarrierState",
    "/x/estimate": "feeder_ros/msg/VehicleEstimate",
    "/cell1/drive/command": "feeder_ros/msg/DriveCommand",
    "/cell1/drive/state": "feeder_ros/msg/DriveState",
    "/cell1/parts": "feeder_ros/msg/PartStateArray",
}


def write_bag(
    path: Path, n: int = 600, **writer_kwargs: Any
) -> dict[str, list[tuple[int, int, bytes]]]:
    """Write ``n`` messages round-robin over TOPICS; returns topic -> [(log, pub, data)]."""
    rng = np.random.default_rng(RNG_SEED)
    written: dict[str, list[tuple[int, int, bytes]]] = {t: [] for t in TOPICS}
    names = list(TOPICS)
    with BagWriter(path, **writer_kwargs) as writer:
        for topic, type_name in TOPICS.items():
            writer.add_topic(topic, type_name)
        for i in range(n):
            topic = names[i % len(names)]
            log = T0 + i * 1_000_000  # 1 kHz overall
            pub = log - 1234
            data = serialize_message(MAKERS[TOPICS[topic]](rng, log - 500_000))
            writer.write(topic, data, log, pub)
            written[topic].append((log, pub, data))
    return written


def _msg_class(type_name: str) -> Any:
    return {
        "sensor_msgs/msg/Imu": Imu,
        "feeder_ros/msg/CarrierState": CarrierState,
        "feeder_ros/msg/VehicleEstimate": VehicleEstimate,
        "feeder_ros/msg/DriveCommand": DriveCommand,
        "feeder_ros/msg/DriveState": DriveState,
        "feeder_ros/msg/PartStateArray": PartStateArray,
    }[type_name]


def _attr(msg: Any, path: str) -> Any:
    for part in path.split("."):
        msg = getattr(msg, part)
    return msg


def assert_same(expected: Any, actual: Any, where: str) -> None:
    if isinstance(expected, float):
        assert (math.isnan(expected) and math.isnan(actual)) or expected == actual, where
    elif isinstance(expected, str | bool | int):
        assert expected == actual, where
    else:
        np.testing.assert_array_equal(np.asarray(actual), np.asarray(expected), err_msg=where)


@pytest.fixture(scope="module")
def bag(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, dict[str, list[tuple[int, int, bytes]]]]:
    path = tmp_path_factory.mktemp("bags") / "run"
    return path, write_bag(path, chunk_size=8 * 1024)


# --------------------------------------------------------------------------- metadata & files


def test_metadata_yaml_is_rosbag2_version_9(bag: tuple[Path, Any]) -> None:
    path, written = bag
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9
    assert info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["run_0.mcap"]
    assert info["message_count"] == 600
    assert info["starting_time"]["nanoseconds_since_epoch"] == T0
    assert info["duration"]["nanoseconds"] == 599 * 1_000_000
    assert info["files"] == [
        {
            "path": "run_0.mcap",
            "starting_time": {"nanoseconds_since_epoch": T0},
            "duration": {"nanoseconds": 599 * 1_000_000},
            "message_count": 600,
        }
    ]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert set(topics) == set(TOPICS)
    for name, entry in topics.items():
        meta = entry["topic_metadata"]
        assert meta["type"] == TOPICS[name]
        assert meta["serialization_format"] == "cdr"
        assert meta["type_description_hash"].startswith("RIHS01_")
        assert meta["offered_qos_profiles"][0]["reliability"] == "reliable"
        assert entry["message_count"] == len(written[name]) == 100
    assert info["ros_distro"]


def test_rosbags_reads_every_message(bag: tuple[Path, Any]) -> None:
    path, written = bag
    store = get_typestore(Stores.ROS2_JAZZY)
    with RosbagsReader(path) as reader:
        assert reader.message_count == 600
        assert reader.start_time == T0
        assert reader.end_time == T0 + 599 * 1_000_000 + 1  # rosbags: exclusive end
        got: dict[str, list[tuple[int, bytes]]] = {t: [] for t in TOPICS}
        for conn in reader.connections:
            if conn.msgtype.startswith("feeder_ros/"):
                store.register(get_string_typestore_types(conn.msgdef.data, conn.msgtype))
        for conn, t, raw in reader.messages():
            got[conn.topic].append((t, raw))
            msg = store.deserialize_cdr(raw, conn.msgtype)
            expected = deserialize_message(raw, _msg_class(conn.msgtype))
            assert msg.header.frame_id == expected.header.frame_id
            assert msg.header.stamp.nanosec == expected.header.stamp.nanosec
    for topic, rows in written.items():
        assert [(log, data) for log, _, data in rows] == [(t, bytes(raw)) for t, raw in got[topic]]


def get_string_typestore_types(msgdef: str, msgtype: str) -> Any:
    """Types of a full ros2msg schema (every dependency) in the form rosbags registers."""
    types: dict[str, Any] = {}
    sections = msgdef.split("=" * 80 + "\n")
    types.update(get_types_from_msg(sections[0], msgtype))
    for section in sections[1:]:
        head, _, body = section.partition("\n")
        name = head.removeprefix("MSG: ").strip()
        pkg, typ = name.split("/")
        types.update(get_types_from_msg(body, f"{pkg}/msg/{typ}"))
    return types


def test_mcap_package_reads_every_record(bag: tuple[Path, Any]) -> None:
    path, written = bag
    with (path / "run_0.mcap").open("rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert summary.statistics.message_count == 600
        assert summary.statistics.message_start_time == T0
        assert summary.statistics.message_end_time == T0 + 599 * 1_000_000
        assert len(summary.chunk_indexes) > 5
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "ros2msg"
            assert schema.name == TOPICS[channel.topic]
            assert schema.data.decode() == ros2msg_schema(schema.name)
            assert channel.message_encoding == "cdr"
            qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
            assert qos[0]["durability"] == "volatile"
        got: dict[str, list[tuple[int, int, bytes]]] = {t: [] for t in TOPICS}
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            got[channel.topic].append((message.log_time, message.publish_time, message.data))
        assert got == written
        (meta,) = list(reader.iter_metadata())
        assert meta.name == "rosbag2"
        inner = yaml.safe_load(meta.metadata["serialized_metadata"])
        assert inner["message_count"] == 600
        assert meta.metadata["ROS_DISTRO"]


def test_schema_holds_every_dependency() -> None:
    text = ros2msg_schema("sensor_msgs/msg/Imu")
    for dep in (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Quaternion",
        "geometry_msgs/Vector3",
    ):
        assert f"{'=' * 80}\nMSG: {dep}\n" in text
    assert text.count("MSG: ") == 4
    parts = ros2msg_schema("feeder_ros/msg/PartStateArray")
    assert "MSG: feeder_ros/PartState\n" in parts


# --------------------------------------------------------------------------- our reader


def test_bag_info_counts_and_range(bag: tuple[Path, Any]) -> None:
    path, written = bag
    info = bag_info(path)
    assert info.message_count == 600
    assert info.start_ns == T0
    assert info.end_ns == T0 + 599 * 1_000_000
    assert not info.cut_short
    assert info.problems == []
    assert info.types() == TOPICS
    for topic, rows in written.items():
        assert info.topics[topic].message_count == len(rows)
        assert info.topics[topic].first_ns == rows[0][0]
        assert info.topics[topic].last_ns == rows[-1][0]
    assert bag_info(path, verify=True).message_count == 600


@pytest.mark.parametrize(
    "type_name",
    [
        "sensor_msgs/msg/Imu",
        "feeder_ros/msg/CarrierState",
        "feeder_ros/msg/VehicleEstimate",
        "feeder_ros/msg/DriveCommand",
        "feeder_ros/msg/DriveState",
    ],
)
def test_columns_equal_rclpy(bag: tuple[Path, Any], type_name: str) -> None:
    path, written = bag
    (topic,) = [t for t, ty in TOPICS.items() if ty == type_name]
    batches = list(read_columns(path, type_name))
    assert {b.topic for b in batches} == {topic}
    cols = concat_batches(batches)
    rows = written[topic]
    assert len(cols[LOG_TIME]) == len(rows)
    np.testing.assert_array_equal(cols[LOG_TIME], [r[0] for r in rows])
    np.testing.assert_array_equal(cols[PUBLISH_TIME], [r[1] for r in rows])
    cls = _msg_class(type_name)
    for i, (_, _, data) in enumerate(rows):
        expected = deserialize_message(data, cls)
        for name, col in cols.items():
            if name.startswith("_"):
                continue
            assert_same(
                _attr(expected, name),
                col[i].item() if col.ndim == 1 and col.dtype != object else col[i],
                f"{name}[{i}]",
            )


def test_short_type_name_and_field_selection(bag: tuple[Path, Any]) -> None:
    path, _ = bag
    cols = concat_batches(
        read_columns(
            path,
            "sensor_msgs/Imu",
            ["linear_acceleration", "linear_acceleration_covariance", "header.stamp"],
        )
    )
    assert set(cols) == {
        "linear_acceleration.x",
        "linear_acceleration.y",
        "linear_acceleration.z",
        "linear_acceleration_covariance",
        "header.stamp.sec",
        "header.stamp.nanosec",
        LOG_TIME,
        PUBLISH_TIME,
    }
    assert cols["linear_acceleration_covariance"].shape == (100, 9)
    with pytest.raises(KeyError, match="no field"):
        next(read_columns(path, "sensor_msgs/Imu", ["nope"]))


def test_sequence_of_messages(bag: tuple[Path, Any]) -> None:
    path, written = bag
    rows = written["/cell1/parts"]
    expected = [deserialize_message(data, PartStateArray) for _, _, data in rows]
    cols = concat_batches(read_columns(path, "feeder_ros/msg/PartStateArray"))
    np.testing.assert_array_equal(cols["parts._count"], [len(e.parts) for e in expected])
    parts = [p for e in expected for p in e.parts]
    np.testing.assert_array_equal(cols["parts.part_id"], [p.part_id for p in parts])
    np.testing.assert_array_equal(cols["parts.position_m"], [p.position_m for p in parts])
    np.testing.assert_array_equal(cols["parts.on_track"], [p.on_track for p in parts])
    assert list(cols["header.frame_id"]) == [e.header.frame_id for e in expected]
    msgs = list(iter_messages(path, types=["feeder_ros/PartStateArray"]))
    assert len(msgs) == 100
    for msg, (log, pub, data), exp in zip(msgs, rows, expected, strict=True):
        assert (msg.log_time_ns, msg.publish_time_ns, msg.data) == (log, pub, data)
        decoded = msg.decode()
        assert decoded["header"]["frame_id"] == exp.header.frame_id
        assert len(decoded["parts"]) == len(exp.parts)
        for got, part in zip(decoded["parts"], exp.parts, strict=True):
            assert got["part_id"] == part.part_id
            assert_same(part.position_m, got["position_m"], "position_m")
            assert got["on_track"] == part.on_track


def test_iter_messages_in_order_and_topic_filter(bag: tuple[Path, Any]) -> None:
    path, written = bag
    msgs = list(iter_messages(path))
    assert [m.log_time_ns for m in msgs] == [T0 + i * 1_000_000 for i in range(600)]
    only = list(iter_messages(path, topics=["/x/estimate"]))
    assert [m.data for m in only] == [r[2] for r in written["/x/estimate"]]
    decoded = only[3].decode()
    expected = deserialize_message(only[3].data, VehicleEstimate)
    assert decoded["status_message"] == expected.status_message


# --------------------------------------------------------------------------- options


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_compressions(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "bag"
    written = write_bag(path, n=120, compression=compression, chunk_size=4096)
    with (path / "bag_0.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        assert {c.compression for c in summary.chunk_indexes} == {
            "" if compression == "none" else compression
        }
    with RosbagsReader(path) as reader:
        assert reader.message_count == 120
        assert sum(1 for _ in reader.messages()) == 120
    cols = concat_batches(read_columns(path, "feeder_ros/msg/CarrierState"))
    expected = [
        deserialize_message(d, CarrierState).velocity_mps
        for _, _, d in written["/cell1/feeder/carrier_state"]
    ]
    np.testing.assert_array_equal(cols["velocity_mps"], expected)


def test_split_by_size(tmp_path: Path) -> None:
    path = tmp_path / "big"
    written = write_bag(path, n=1200, chunk_size=4096, max_file_size=20_000)
    files = sorted(path.glob("*.mcap"))
    assert len(files) >= 3
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == [f"big_{i}.mcap" for i in range(len(files))]
    assert sum(f["message_count"] for f in info["files"]) == 1200
    starts = [f["starting_time"]["nanoseconds_since_epoch"] for f in info["files"]]
    assert starts == sorted(starts)
    for f in files[:-1]:
        # one chunk of overshoot at most, before the summary (schemas, indexes: its size grows
        # with the message definitions, not with the data); the footer says where it starts:
        # ... summary_start u64, summary_offset_start u64, summary_crc u32, magic (8 bytes)
        tail = f.read_bytes()[-28:]
        summary_start = int.from_bytes(tail[:8], "little")
        assert 0 < summary_start < 20_000 + 8 * 4096, (f.name, summary_start)
    with RosbagsReader(path) as reader:
        assert reader.message_count == 1200
        assert sum(1 for _ in reader.messages()) == 1200
    assert bag_info(path).message_count == 1200
    msgs = list(iter_messages(path))
    assert [m.log_time_ns for m in msgs] == [T0 + i * 1_000_000 for i in range(1200)]
    cols = concat_batches(read_columns(path, "sensor_msgs/msg/Imu"))
    np.testing.assert_array_equal(cols[LOG_TIME], [r[0] for r in written["/cell1/imu/data_raw"]])


def test_split_by_duration(tmp_path: Path) -> None:
    path = tmp_path / "dur"
    write_bag(path, n=600, max_file_duration_ns=200_000_000)  # 0.2 s per file at 1 kHz
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert [f["message_count"] for f in info["files"]] == [200, 200, 200]
    assert [f["starting_time"]["nanoseconds_since_epoch"] for f in info["files"]] == [
        T0,
        T0 + 200_000_000,
        T0 + 400_000_000,
    ]
    with RosbagsReader(path) as reader:
        assert reader.message_count == 600
    assert bag_info(path).message_count == 600


def test_single_mcap_file_can_be_read(bag: tuple[Path, Any]) -> None:
    path, _ = bag
    one = Bag(path / "run_0.mcap")
    assert one.metadata is None
    cols = concat_batches(read_columns(one, "feeder_ros/msg/DriveCommand"))
    assert len(cols[LOG_TIME]) == 100
    assert Bag(path / "metadata.yaml").files == [path / "run_0.mcap"]


def test_mcap_writer_files_with_schemas_inside_chunks(tmp_path: Path) -> None:
    """A file from another writer (the mcap package puts schemas and channels into chunks)."""
    from mcap.writer import Writer

    rng = np.random.default_rng(1)
    path = tmp_path / "other.mcap"
    datas = [serialize_message(make_imu(rng, T0 + i)) for i in range(50)]
    with path.open("wb") as f:
        w = Writer(f, chunk_size=2000)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(
            "sensor_msgs/msg/Imu", "ros2msg", ros2msg_schema("sensor_msgs/msg/Imu").encode()
        )
        cid = w.register_channel("/robot/imu", "cdr", sid, {"offered_qos_profiles": ""})
        other = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        oid = w.register_channel("/chatter", "cdr", other)
        for i, d in enumerate(datas):
            w.add_message(cid, T0 + i, d, T0 + i)
            w.add_message(oid, T0 + i, serialize_message(_string("hi")), T0 + i)
        w.finish()
    cols = concat_batches(read_columns(path, "sensor_msgs/msg/Imu"))
    assert len(cols[LOG_TIME]) == 50
    for i, d in enumerate(datas):
        assert_same(
            deserialize_message(d, Imu).angular_velocity.y,
            cols["angular_velocity.y"][i].item(),
            "y",
        )
    assert bag_info(path).topics["/chatter"].message_count == 50


def _string(text: str) -> Any:
    from std_msgs.msg import String

    return String(data=text)


def test_rosbags_parses_our_schema_text() -> None:
    # rosbags' own ros2msg parsing of our schema text yields the same field names as rclpy.
    store = get_typestore(Stores.EMPTY)
    store.register(
        get_string_typestore_types(
            ros2msg_schema("feeder_ros/msg/VehicleEstimate"), "feeder_ros/msg/VehicleEstimate"
        )
    )
    fields = [name for name, _ in store.fielddefs["feeder_ros/msg/VehicleEstimate"][1]]
    assert fields == list(VehicleEstimate.get_fields_and_field_types())


def test_out_of_order_log_times(tmp_path: Path) -> None:
    """Late messages: indexes stay sorted by log time; readers see file order or time order."""
    path = tmp_path / "ooo"
    rng = np.random.default_rng(5)
    times = T0 + rng.permutation(200).astype(np.int64) * 1_000
    datas = [serialize_message(make_carrier(rng, int(t))) for t in times]
    with BagWriter(path, chunk_size=2048) as writer:
        writer.add_topic("/state", "feeder_ros/msg/CarrierState")
        for t, data in zip(times.tolist(), datas, strict=True):
            writer.write("/state", data, t)
    cols = concat_batches(read_columns(path, "feeder_ros/msg/CarrierState", ["velocity_mps"]))
    np.testing.assert_array_equal(cols[LOG_TIME], times)  # file order
    with (path / "ooo_0.mcap").open("rb") as f:
        ordered = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=True)]
    assert ordered == sorted(times.tolist())
    info = bag_info(path)
    assert (info.start_ns, info.end_ns) == (T0, T0 + 199_000)
    with RosbagsReader(path) as reader:
        assert [t for _, t, _ in reader.messages()] == sorted(times.tolist())
