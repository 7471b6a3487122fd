"""Damaged and unusual bags: truncated files, corrupt chunks, missing metadata, empty bags,
unknown schemas, malformed messages, and a writer killed with SIGKILL in a real subprocess."""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from sensor_msgs.msg import Imu

from feeder_ros.bag import (
    LOG_TIME,
    Bag,
    BagWarning,
    BagWriter,
    MissingBagError,
    WriterStateError,
    bag_info,
    concat_batches,
    iter_messages,
    read_columns,
    reindex,
)
from feeder_ros.msg import CarrierState

T0 = 1_800_000_000_000_000_000
REPO = Path(__file__).resolve().parents[2]


def imu(i: int) -> bytes:
    m = Imu()
    m.header.stamp.sec = i
    m.header.frame_id = "imu" * (i % 4)
    m.linear_acceleration.x = i * 0.5
    return bytes(serialize_message(m))


def write_imu_bag(path: Path, n: int, compression: str = "zstd", chunk_size: int = 4096) -> None:
    with BagWriter(path, compression=compression, chunk_size=chunk_size) as writer:
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
        for i in range(n):
            writer.write("/imu", imu(i), T0 + i * 1_000_000)


def chunk_offsets(path: Path) -> list[tuple[int, int]]:
    """(offset, length) of every chunk record, from the summary (read by the mcap package)."""
    return [(c.chunk_start_offset, c.chunk_length) for c in chunk_indexes(path)]


def chunk_indexes(path: Path) -> list[Any]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        return list(summary.chunk_indexes)


def messages_in(index: Any) -> int:
    """Messages of a chunk of write_imu_bag (one every millisecond), from its time range."""
    return (index.message_end_time - index.message_start_time) // 1_000_000 + 1


def kinds(bag: Bag) -> list[str]:
    return [p.kind for p in bag.problems]


def read_x(bag: Bag) -> np.ndarray:
    cols = concat_batches(read_columns(bag, "sensor_msgs/msg/Imu", ["linear_acceleration.x"]))
    return cols.get("linear_acceleration.x", np.empty(0))


# --------------------------------------------------------------------------- truncation


def test_truncated_file_reads_complete_chunks(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 400)
    mcap = path / "bag_0.mcap"
    indexes = chunk_indexes(mcap)
    assert len(indexes) >= 10
    # Cut in the middle of chunk 5: chunks 0..4 are complete.
    off, length = indexes[5].chunk_start_offset, indexes[5].chunk_length
    data = mcap.read_bytes()[: off + length // 2]
    mcap.write_bytes(data)
    bag = Bag(path, warn=False)
    x = read_x(bag)
    assert len(x) == sum(messages_in(c) for c in indexes[:5])
    np.testing.assert_array_equal(x, np.arange(len(x)) * 0.5)
    assert bag.cut_short
    # the file is cut, the chunk the cut went through is lost, and metadata.yaml (written when
    # the bag was closed) counts the 400 messages recorded: the rest are counted lost
    assert kinds(bag) == ["cut_short", "cut_chunk", "lost_messages"]
    problem, cut, lost = bag.problems
    assert problem.file == mcap
    assert problem.offset == off
    assert "without a footer" in str(problem) or "file ends" in str(problem)
    assert (cut.file, cut.offset) == (mcap, off)
    assert bag.loss is not None
    assert (bag.loss.recorded, bag.loss.readable, bag.loss.lost) == (400, len(x), 400 - len(x))
    assert bag.loss.exact
    assert f"{400 - len(x)} of 400 recorded messages lost" in lost.detail
    info = bag_info(Bag(path, warn=False))
    assert info.cut_short == bag.cut_short
    assert info.message_count == len(x)
    assert info.loss == bag.loss


@pytest.mark.parametrize("cut", [9, 20, 100])
def test_truncated_inside_the_header_area(tmp_path: Path, cut: int) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 50)
    mcap = path / "bag_0.mcap"
    mcap.write_bytes(mcap.read_bytes()[:cut])
    bag = Bag(path, warn=False)
    assert len(read_x(bag)) == 0
    assert bag.cut_short


def test_reindex_finishes_a_truncated_file(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 400)
    mcap = path / "bag_0.mcap"
    indexes = chunk_indexes(mcap)
    mcap.write_bytes(mcap.read_bytes()[: indexes[7].chunk_start_offset + 20])
    expected = sum(messages_in(c) for c in indexes[:7])
    info = reindex(path)
    assert info.message_count == expected
    assert not info.cut_short
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert summary.statistics.message_count == expected
    with RosbagsReader(path) as reader:
        assert reader.message_count == expected
        assert reader.end_time == T0 + (expected - 1) * 1_000_000 + 1
    np.testing.assert_array_equal(read_x(Bag(path, warn=False)), np.arange(expected) * 0.5)
    assert reindex(path).message_count == expected  # idempotent on a complete bag


def test_not_an_mcap_file(tmp_path: Path) -> None:
    path = tmp_path / "junk.mcap"
    path.write_bytes(b"hello world, not a bag")
    bag = Bag(path, warn=False)
    assert list(iter_messages(bag)) == []
    assert kinds(bag) == ["not_mcap"]
    assert str(path) in str(bag.problems[0])


# --------------------------------------------------------------------------- corrupt chunks


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_corrupt_chunk_is_skipped_and_named(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 300, compression=compression)
    mcap = path / "bag_0.mcap"
    indexes = chunk_indexes(mcap)
    off, length = indexes[2].chunk_start_offset, indexes[2].chunk_length
    data = bytearray(mcap.read_bytes())
    middle = off + length // 2
    data[middle : middle + 8] = bytes(b ^ 0xFF for b in data[middle : middle + 8])
    mcap.write_bytes(bytes(data))
    bag = Bag(path)
    with (
        pytest.warns(BagWarning, match="chunk skipped"),
        pytest.warns(BagWarning, match=rf"\[lost_messages\] {messages_in(indexes[2])} of 300"),
    ):
        x = read_x(bag)
    assert len(x) == 300 - messages_in(indexes[2])
    # bag_info counts from the message indexes without decompressing; verify=True decompresses.
    assert bag_info(Bag(path, warn=False)).message_count == 300
    assert bag_info(Bag(path, warn=False), verify=True).message_count == len(x)
    corrupt = [p for p in bag.problems if p.kind == "corrupt_chunk"]
    assert len(corrupt) == 1
    assert corrupt[0].offset == off
    assert corrupt[0].file == mcap
    assert not bag.cut_short
    # Every message that was read is intact and in order.
    i = np.rint(x / 0.5).astype(int)
    np.testing.assert_array_equal(x, i * 0.5)
    assert np.all(np.diff(i) > 0)


def test_crc_check_can_be_switched_off(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 100, compression="none")
    mcap = path / "bag_0.mcap"
    index = chunk_indexes(mcap)[1]
    data = bytearray(mcap.read_bytes())
    data[index.chunk_start_offset + index.chunk_length - 3] ^= 0x55  # inside a message's data
    mcap.write_bytes(bytes(data))
    checked = Bag(path, warn=False)
    assert len(read_x(checked)) == 100 - messages_in(index)
    assert [p.kind for p in checked.problems] == ["corrupt_chunk", "lost_messages"]
    assert "CRC mismatch" in checked.problems[0].detail
    assert checked.loss is not None
    assert (checked.loss.recorded, checked.loss.lost) == (100, messages_in(index))
    unchecked = Bag(path, warn=False, verify_crc=False)
    assert len(read_x(unchecked)) == 100
    assert unchecked.problems == []


@pytest.mark.parametrize("damage", ["length", "opcode"])
def test_bad_record_header_resumes_at_the_next_chunk(tmp_path: Path, damage: str) -> None:
    """A broken record header cannot be stepped over; the summary tells where the next chunk is."""
    path = tmp_path / "bag"
    write_imu_bag(path, 200)
    mcap = path / "bag_0.mcap"
    indexes = chunk_indexes(mcap)
    off = indexes[3].chunk_start_offset
    data = bytearray(mcap.read_bytes())
    if damage == "length":
        struct.pack_into("<Q", data, off + 1, 1 << 40)
    else:
        data[off] = 0x7F
    mcap.write_bytes(bytes(data))
    bag = Bag(path, warn=False)
    x = read_x(bag)
    assert len(x) == 200 - messages_in(indexes[3])
    i = np.rint(x / 0.5).astype(int)
    np.testing.assert_array_equal(x, i * 0.5)
    skipped = np.setdiff1d(np.arange(200), i)
    first = (indexes[3].message_start_time - T0) // 1_000_000
    np.testing.assert_array_equal(skipped, np.arange(first, first + messages_in(indexes[3])))
    problem, lost = bag.problems
    assert problem.kind == "corrupt_record"
    assert lost.kind == "lost_messages"
    assert bag.loss is not None  # counted from the summary's statistics and metadata.yaml
    assert (bag.loss.recorded, bag.loss.lost, bag.loss.exact) == (200, len(skipped), True)
    assert problem.offset == off
    assert f"bytes {off}..{indexes[4].chunk_start_offset} skipped" in problem.detail
    assert not bag.cut_short


def test_bad_record_header_without_footer_stops_the_file(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 200)
    mcap = path / "bag_0.mcap"
    indexes = chunk_indexes(mcap)
    off = indexes[3].chunk_start_offset
    data = bytearray(mcap.read_bytes())
    data[off] = 0x7F
    mcap.write_bytes(bytes(data[: indexes[6].chunk_start_offset]))
    bag = Bag(path, warn=False)
    read = sum(messages_in(c) for c in indexes[:3])
    assert len(read_x(bag)) == read
    assert [p.kind for p in bag.problems] == ["corrupt_record", "lost_messages"]
    assert "unknown opcode 0x7f" in str(bag.problems[0])
    assert bag.loss is not None  # metadata.yaml counts what the file held
    assert (bag.loss.recorded, bag.loss.lost) == (200, 200 - read)


# --------------------------------------------------------------------------- metadata & empty


def test_missing_metadata_yaml(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    write_imu_bag(path, 100)
    (path / "metadata.yaml").unlink()
    with pytest.warns(BagWarning, match="metadata.yaml"):
        bag = Bag(path)
    assert kinds(bag) == ["missing_metadata"]
    assert len(read_x(bag)) == 100


def test_missing_file_listed_in_metadata(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path, max_file_duration_ns=50_000_000) as writer:
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
        for i in range(150):
            writer.write("/imu", imu(i), T0 + i * 1_000_000)
    (path / "bag_1.mcap").unlink()
    bag = Bag(path, warn=False)
    assert kinds(bag) == ["missing_file"]
    assert "bag_1.mcap" in str(bag.problems[0])
    assert len(read_x(bag)) == 100


def test_relative_file_paths_not_a_list_is_named(tmp_path: Path) -> None:
    """A string where metadata.yaml needs a list is not read character by character."""
    path = tmp_path / "bag"
    write_imu_bag(path, 50)
    meta = path / "metadata.yaml"
    data = yaml.safe_load(meta.read_text())
    data["rosbag2_bagfile_information"]["relative_file_paths"] = "bag_0.mcap"
    meta.write_text(yaml.safe_dump(data))
    bag = Bag(path, warn=False)
    assert kinds(bag) == ["bad_metadata"]
    assert "relative_file_paths is not a list of file names: 'bag_0.mcap'" in str(bag.problems[0])
    assert bag.files == [path / "bag_0.mcap"]
    assert len(read_x(bag)) == 50


def split_imu_bag(path: Path) -> None:
    """150 IMU messages (1 ms apart) in three files of 50, a few chunks each."""
    with BagWriter(path, chunk_size=4096, max_file_duration_ns=50_000_000) as writer:
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
        for i in range(150):
            writer.write("/imu", imu(i), T0 + i * 1_000_000)
    assert sorted(p.name for p in path.glob("*.mcap")) == [f"bag_{i}.mcap" for i in range(3)]


def test_lost_data_names_the_losses_but_not_a_cut_last_file(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    split_imu_bag(path)
    last = path / "bag_2.mcap"
    last.write_bytes(last.read_bytes()[:-100])
    bag = Bag(path, warn=False)
    assert len(read_x(bag)) == 150
    assert kinds(bag) == ["cut_short"]
    assert bag.lost_data() == []  # a killed recorder: what was read is whole up to the cut
    middle = path / "bag_1.mcap"
    middle.write_bytes(middle.read_bytes()[:-100])
    bag = Bag(path, warn=False)
    read_x(bag)
    assert [(p.kind, p.file) for p in bag.lost_data()] == [("cut_short", middle)]
    middle.write_bytes(b"")
    bag = Bag(path, warn=False)
    assert len(read_x(bag)) == 100
    # and the count: metadata.yaml lists the file's 50 messages, none readable
    assert [(p.kind, p.file) for p in bag.lost_data()] == [
        ("not_mcap", middle),
        ("lost_messages", None),
    ]
    assert bag.loss is not None
    assert (bag.loss.recorded, bag.loss.lost, bag.loss.exact) == (150, 50, True)
    middle.unlink()
    bag = Bag(path, warn=False)
    (lost,) = bag.lost_data()
    assert (lost.kind, lost.file) == ("missing_file", middle)
    # what the metadata said of the missing file: 50 messages 1 ms apart
    assert lost.lost_ns == 49_000_000


def test_reindex_leaves_damaged_files_as_they_are(tmp_path: Path) -> None:
    """Only a file that is merely cut short is rewritten; a file that is not MCAP, or damaged
    before its cut, keeps its bytes (a rewrite would lose what lies past the damage), and a
    missing split file stays listed in metadata.yaml."""
    path = tmp_path / "bag"
    split_imu_bag(path)
    first, middle, last = (path / f"bag_{i}.mcap" for i in range(3))
    first.write_bytes(b"overwritten by something else")  # not MCAP
    data = bytearray(middle.read_bytes())
    off = chunk_indexes(middle)[1].chunk_start_offset
    data[off] = 0x7F  # a damaged record header, and no footer: nothing after it can be found
    middle.write_bytes(bytes(data[: len(data) - 200]))
    last.write_bytes(last.read_bytes()[: chunk_indexes(last)[-1].chunk_start_offset + 10])
    before = {p: p.read_bytes() for p in (first, middle)}
    info = reindex(path)
    assert {p: p.read_bytes() for p in (first, middle)} == before
    not_finished = [p for p in info.problems if p.kind == "not_finished"]
    assert [p.file for p in not_finished] == [first, middle]
    assert "damaged (not_mcap)" in not_finished[0].detail
    assert "damaged (corrupt_record)" in not_finished[1].detail
    with last.open("rb") as f:  # the cut-short last file was finished
        summary = make_reader(f).get_summary()
        assert summary is not None
    # the third file's complete chunks, and the middle file's chunk before the damage, are read
    x = read_x(Bag(path, warn=False))
    assert len(x) == info.message_count > 0
    # a corrupt chunk in a cut-short file: counting reads only the indexes and misses it; the
    # rewrite's full read finds it, and the file is left as it is
    path = tmp_path / "chunk" / "bag"
    split_imu_bag(path)
    last = path / "bag_2.mcap"
    data = bytearray(last.read_bytes())
    index = chunk_indexes(last)[1]
    at = index.chunk_start_offset + index.chunk_length // 2
    data[at : at + 64] = bytes(64)
    last.write_bytes(bytes(data[: chunk_indexes(last)[-1].chunk_start_offset + 10]))
    before_last = last.read_bytes()
    info = reindex(path)
    assert last.read_bytes() == before_last
    (not_finished,) = [p for p in info.problems if p.kind == "not_finished"]
    assert not_finished.file == last
    assert "damaged (corrupt_chunk)" in not_finished.detail
    # a missing file stays listed, with what the old metadata.yaml said of it
    path = tmp_path / "other" / "bag"
    split_imu_bag(path)
    (path / "bag_1.mcap").unlink()
    info = reindex(path)
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == ["bag_0.mcap", "bag_1.mcap", "bag_2.mcap"]
    assert meta["files"][1]["path"] == "bag_1.mcap"
    assert meta["files"][1]["message_count"] == 50
    assert meta["files"][1]["starting_time"]["nanoseconds_since_epoch"] == T0 + 50_000_000
    assert meta["message_count"] == info.message_count == 100  # the messages there
    assert kinds(Bag(path, warn=False)) == ["missing_file"]


def test_reindex_keeps_two_types_on_one_topic_name(tmp_path: Path) -> None:
    """A cut-short file (another writer's) where one topic name carries two types: the rewrite
    keeps each message on its own channel and type, and metadata.yaml lists both."""
    from mcap.writer import Writer as McapWriter

    from feeder_ros.bag import ros2msg_schema

    path = tmp_path / "bag"
    path.mkdir()
    mcap = path / "bag_0.mcap"
    with mcap.open("wb") as stream:
        writer = McapWriter(stream, chunk_size=2048)
        writer.start("ros2", "test")
        ids = {}
        for type_name in ("sensor_msgs/msg/Imu", "feeder_ros/msg/CarrierState"):
            schema = writer.register_schema(
                type_name, "ros2msg", ros2msg_schema(type_name).encode()
            )
            ids[type_name] = writer.register_channel("/x", "cdr", schema)
        for i in range(100):
            writer.add_message(ids["sensor_msgs/msg/Imu"], T0 + 2 * i, imu(i), T0 + 2 * i)
            state = bytes(serialize_message(CarrierState(velocity_mps=float(i))))
            writer.add_message(ids["feeder_ros/msg/CarrierState"], T0 + 2 * i + 1, state, T0)
        writer.finish()
    mcap.write_bytes(mcap.read_bytes()[: chunk_indexes(mcap)[-1].chunk_start_offset + 10])
    info = reindex(path)
    assert not info.cut_short
    imu_x = read_x(Bag(path, warn=False))
    states = concat_batches(read_columns(path, "feeder_ros/msg/CarrierState", ["velocity_mps"]))
    assert len(imu_x) > 20
    np.testing.assert_array_equal(imu_x, np.arange(len(imu_x)) * 0.5)
    np.testing.assert_array_equal(states["velocity_mps"], np.arange(len(states["velocity_mps"])))
    assert abs(len(imu_x) - len(states["velocity_mps"])) <= 1
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    listed = sorted(
        (t["topic_metadata"]["name"], t["topic_metadata"]["type"], t["message_count"])
        for t in meta["topics_with_message_count"]
    )
    assert listed == [
        ("/x", "feeder_ros/msg/CarrierState", len(states["velocity_mps"])),
        ("/x", "sensor_msgs/msg/Imu", len(imu_x)),
    ]
    with mcap.open("rb") as f:  # the summary's counts: every channel, none lost to its name
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert sorted(summary.statistics.channel_message_counts.values()) == sorted(
        [len(imu_x), len(states["velocity_mps"])]
    )


@pytest.mark.parametrize("field", ["acme_msgs/Node[] kids", "acme_msgs/Node next"])
def test_recursive_schema_is_an_unknown_schema(tmp_path: Path, field: str) -> None:
    """A schema whose type contains itself is corrupt: named, not a RecursionError."""
    path = tmp_path / "bag"
    schema = f"acme_msgs/Node[] children\n{'=' * 80}\nMSG: acme_msgs/Node\n{field}\n"
    with BagWriter(path) as writer:
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
        writer.add_topic("/tree", "acme_msgs/msg/Tree", schema_text=schema, type_hash="")
        for i in range(5):
            writer.write("/imu", imu(i), T0 + i)
            writer.write("/tree", b"\x00\x01\x00\x00" + struct.pack("<I", 0), T0 + i)
    bag = Bag(path, warn=False)
    assert list(read_columns(bag, "acme_msgs/msg/Tree")) == []
    (problem,) = bag.problems
    assert problem.kind == "unknown_schema"
    assert "recursive (acme_msgs/msg/Node -> acme_msgs/msg/Node)" in problem.detail
    assert len(read_x(bag)) == 5


def test_no_bag_at_all(tmp_path: Path) -> None:
    with pytest.raises(MissingBagError, match="no such file"):
        Bag(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingBagError, match=r"no metadata.yaml and no \.mcap"):
        Bag(tmp_path / "empty")


def test_empty_bag(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path) as writer:
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
    bag = Bag(path, warn=False)
    assert list(read_columns(bag, "sensor_msgs/msg/Imu")) == []
    info = bag_info(path)
    assert info.message_count == 0
    assert info.start_ns is None
    assert info.topics["/imu"].message_count == 0
    assert info.problems == []


def test_writer_errors(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    writer = BagWriter(path)
    with pytest.raises(WriterStateError, match="before add_topic"):
        writer.write("/imu", imu(0), T0)
    writer.close()
    with pytest.raises(WriterStateError, match="closed"):
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
    with pytest.raises(WriterStateError, match="not an empty directory"):
        BagWriter(path)
    with pytest.raises(WriterStateError, match="compression"):
        BagWriter(tmp_path / "b2", compression="gzip")


# --------------------------------------------------------------------------- schemas & messages


def test_unknown_schema_is_reported_and_other_topics_read(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    schema = "acme_msgs/Thing thing\nfloat64 y\n"  # dependency not in the schema, not installed
    with BagWriter(path) as writer:
        writer.add_topic("/imu", "sensor_msgs/msg/Imu")
        writer.add_topic("/thing", "acme_msgs/msg/Widget", schema_text=schema, type_hash="")
        for i in range(20):
            writer.write("/imu", imu(i), T0 + i)
            writer.write("/thing", b"\x00\x01\x00\x00" + struct.pack("<dd", i, i), T0 + i)
    bag = Bag(path, warn=False)
    assert list(read_columns(bag, "acme_msgs/msg/Widget")) == []
    (problem,) = bag.problems
    assert problem.kind == "unknown_schema"
    assert problem.topic == "/thing"
    assert "acme_msgs/msg/Thing" in problem.detail
    assert len(read_x(bag)) == 20
    assert len(list(iter_messages(bag, topics=["/thing"]))) == 20  # raw bytes still available


def test_custom_schema_from_the_bag_is_used(tmp_path: Path) -> None:
    """A type not installed here decodes from the schema recorded in the bag."""
    path = tmp_path / "bag"
    schema = (
        f"acme_msgs/Thing thing\nfloat64 y\n{'=' * 80}\nMSG: acme_msgs/Thing\nuint8 a\nstring b\n"
    )
    with BagWriter(path) as writer:
        writer.add_topic("/ns/thing", "acme_msgs/msg/Widget", schema_text=schema, type_hash="")
        for i in range(30):
            text = ("é" * (i % 3)).encode()
            body = struct.pack("<BxxxI", i, len(text) + 1) + text + b"\x00"
            body += b"\x00" * (-len(body) % 8) + struct.pack("<d", -i)
            writer.write("/ns/thing", b"\x00\x01\x00\x00" + body, T0 + i)
    cols = concat_batches(read_columns(path, "acme_msgs/Widget"))
    np.testing.assert_array_equal(cols["thing.a"], np.arange(30))
    assert list(cols["thing.b"]) == ["é" * (i % 3) for i in range(30)]
    np.testing.assert_array_equal(cols["y"], -np.arange(30.0))
    msgs = list(iter_messages(path))
    assert msgs[4].decode() == {"thing": {"a": 4, "b": "é"}, "y": -4.0}


def test_malformed_messages_are_dropped_and_reported(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    good = serialize_message(CarrierState(velocity_mps=1.5))
    with BagWriter(path) as writer:
        writer.add_topic("/state", "feeder_ros/msg/CarrierState")
        for i in range(10):
            data = good[: len(good) - 8] if i == 3 else good
            writer.write("/state", bytes(data), T0 + i)
        writer.write("/state", b"\x00\x07\x00\x00" + good[4:], T0 + 10)  # XCDR2: not plain CDR
    bag = Bag(path, warn=False)
    cols = concat_batches(read_columns(bag, "feeder_ros/msg/CarrierState"))
    np.testing.assert_array_equal(cols[LOG_TIME], [T0 + i for i in range(10) if i != 3])
    np.testing.assert_array_equal(cols["velocity_mps"], np.full(9, 1.5))
    assert sorted(kinds(bag)) == ["malformed_message", "unsupported_encoding"]
    assert all(p.topic == "/state" for p in bag.problems)
    assert deserialize_message(good, CarrierState).velocity_mps == 1.5


# --------------------------------------------------------------------------- SIGKILL


WRITER_SCRIPT = textwrap.dedent(
    """
    import sys, time
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu
    from feeder_ros.bag import BagWriter

    writer = BagWriter(sys.argv[1], chunk_size=4096, max_file_size=60_000)
    writer.add_topic("/imu", "sensor_msgs/msg/Imu")
    i = 0
    while True:
        m = Imu()
        m.header.stamp.sec = i
        m.linear_acceleration.x = i * 0.5
        writer.write("/imu", bytes(serialize_message(m)), 1_000_000_000 + i * 1_000_000)
        if i == 3000:
            print("written", flush=True)
        i += 1
        if i > 3000:
            time.sleep(0.0002)
    """
)


@pytest.mark.slow
def test_sigkilled_writer_leaves_a_readable_bag(tmp_path: Path) -> None:
    path = tmp_path / "killed"
    script = tmp_path / "writer.py"
    script.write_text(WRITER_SCRIPT)
    proc = subprocess.Popen(
        [sys.executable, str(script), str(path)],
        stdout=subprocess.PIPE,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.strip() == b"written", line
        time.sleep(0.3)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    files = sorted(path.glob("*.mcap"))
    assert len(files) >= 2  # it split at least once before the kill
    assert (path / "metadata.yaml").is_file()
    bag = Bag(path, warn=False)
    x = read_x(bag)
    # The kill nearly always lands while the last file is open (no footer yet): "cut_short". In
    # the rare window of a split the last file may be complete, or not yet in metadata.yaml.
    last_complete = files[-1].read_bytes().endswith(b"\x89MCAP0\r\n")
    assert bag.cut_short == (not last_complete)
    assert {p.kind for p in bag.problems} <= {"cut_short", "unlisted_file"}
    assert all(p.file == files[-1] for p in bag.problems)
    assert len(x) >= 3000 - 4096 // 300  # everything but the open chunk (and a few at most)
    np.testing.assert_array_equal(x, np.arange(len(x)) * 0.5)  # no gap, no duplicate
    info = bag_info(Bag(path, warn=False))
    assert info.cut_short == bag.cut_short
    assert info.message_count == len(x)
    assert info.start_ns == 1_000_000_000
    # reindex finishes the last file and rewrites metadata.yaml: rosbags reads the bag again.
    fixed = reindex(path)
    assert not fixed.cut_short
    assert fixed.problems[: len(bag.problems)] == bag.problems  # found before the rewrite
    assert fixed.message_count == len(x)
    with RosbagsReader(path) as reader:
        assert reader.message_count == len(x)
        times = [t for _, t, _ in reader.messages()]
    assert times == [1_000_000_000 + i * 1_000_000 for i in range(len(x))]
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == len(x)
    assert [f["path"] for f in meta["files"]] == [f.name for f in files]
    assert sum(f["message_count"] for f in meta["files"]) == len(x)
    clean = Bag(path, warn=False)
    np.testing.assert_array_equal(read_x(clean), x)
    assert clean.problems == []
