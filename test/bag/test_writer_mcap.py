"""The bag writer on ``mcap``'s Writer: what ``mcap``'s own reader finds in a finished file, and
a file cut short (a killed recorder) whose topics appeared mid-recording: a reader that skips
chunks by their indexes, taking one topic, still finds every channel and every message."""

from __future__ import annotations

import warnings
from pathlib import Path

import yaml
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64

from feeder_ros.bag import Bag, BagWriter, iter_messages
from feeder_ros.bag.schemas import ros2msg_schema

T0 = 1_700_000_000_000_000_000
MS = 1_000_000


def cdr(value: float) -> bytes:
    return bytes(serialize_message(Float64(data=float(value))))


def test_mcap_reads_a_finished_file_with_rosbag2_s_records(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag", chunk_size=512) as writer:
        writer.add_topic("/speed", "std_msgs/msg/Float64")
        writer.add_topic("/never", "diagnostic_msgs/msg/DiagnosticArray")  # no message at all
        for i in range(100):
            writer.write("/speed", cdr(i * 0.25), T0 + i * MS)
    with (tmp_path / "bag" / "bag_0.mcap").open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        header = reader.get_header()
        assert (header.profile, header.library) == ("ros2", "feeder_ros.bag")
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {"/speed", "/never"}  # the empty topic too
        speed = channels["/speed"]
        assert speed.message_encoding == "cdr"
        assert set(speed.metadata) == {"offered_qos_profiles", "topic_type_hash"}
        schema = summary.schemas[speed.schema_id]
        assert (schema.name, schema.encoding) == ("std_msgs/msg/Float64", "ros2msg")
        assert schema.data.decode() == ros2msg_schema("std_msgs/msg/Float64")
        assert summary.statistics is not None
        assert summary.statistics.message_count == 100
        assert len(summary.chunk_indexes) > 5  # 512-byte chunks
        values = [
            deserialize_message(message.data, Float64).data
            for _, _, message in reader.iter_messages(topics=["/speed"])
        ]
        assert values == [i * 0.25 for i in range(100)]
        [metadata] = list(reader.iter_metadata())
        assert metadata.name == "rosbag2"
        inner = yaml.safe_load(metadata.metadata["serialized_metadata"])  # no top-level key
        assert inner["message_count"] == 100


def test_a_cut_file_with_topics_added_mid_recording_reads_topic_by_topic(tmp_path: Path) -> None:
    # chunks smaller than a schema: the records of a new channel alone would fill one
    writer = BagWriter(tmp_path / "cut", chunk_size=256)
    writer.add_topic("/a", "std_msgs/msg/Float64")
    for i in range(600):
        writer.write("/a", cdr(i), T0 + i * MS)
        if i == 200:
            writer.add_topic("/b", "std_msgs/msg/Float64")
            writer.add_topic("/diag", "diagnostic_msgs/msg/DiagnosticArray")
        if i > 200:
            writer.write("/b", cdr(-i), T0 + i * MS + 1)
    # not closed: as a recorder killed with SIGKILL leaves it (every finished chunk on disk)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bag = Bag(tmp_path / "cut")
        got = [deserialize_message(m.data, Float64).data for m in iter_messages(bag, ["/b"])]
    kinds = {problem.kind for problem in bag.problems}
    assert kinds == {"cut_short"}  # no channel undefined
    assert got == [-i for i in range(201, 201 + len(got))]
    assert len(got) > 350  # all but the last open chunk's
