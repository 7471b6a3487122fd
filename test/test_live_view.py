"""The live view's Foxglove server (feeder_ros.live_view.FoxgloveSink), without ROS: a plain
WebSocket client sees each topic advertised with its ros2msg schema and receives the very CDR
bytes written, which an independent reader (rosbags) decodes from the advertised schema."""

from __future__ import annotations

import socket
import struct
from collections.abc import Iterator

import pytest
from foxglove_client import FoxgloveClient
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from feeder_ros.bag.errors import UnknownTypeError
from feeder_ros.bag.schemas import ros2msg_schema
from feeder_ros.live_view import LOCALHOST, FoxgloveSink, LiveViewError

CDR_LE = b"\x00\x01\x00\x00"  # the encapsulation header of little-endian plain CDR


@pytest.fixture
def sink() -> Iterator[FoxgloveSink]:
    served = FoxgloveSink(port=0)
    try:
        yield served
    finally:
        served.close()


def decode(channel: dict[str, object], payload: bytes) -> object:
    """The message, decoded by rosbags from the schema the server advertised."""
    store = get_typestore(Stores.EMPTY)
    name = str(channel["schemaName"])
    store.register(get_types_from_msg(str(channel["schema"]), name))
    return store.deserialize_cdr(payload, name)


def test_a_topic_is_advertised_with_its_schema_and_its_bytes_arrive_unchanged(
    sink: FoxgloveSink,
) -> None:
    sink.add_topic("/cell/feeder_1/speed", "std_msgs/msg/Float64", "- depth: 10\n")
    assert sink.url == f"ws://127.0.0.1:{sink.port}"
    with FoxgloveClient(sink.url) as client:
        assert client.wait_for(lambda: "/cell/feeder_1/speed" in client.channels, 10.0)
        channel = client.channels["/cell/feeder_1/speed"]
        assert channel["encoding"] == "cdr"
        assert channel["schemaEncoding"] == "ros2msg"
        assert channel["schemaName"] == "std_msgs/msg/Float64"
        assert channel["schema"] == ros2msg_schema("std_msgs/msg/Float64")
        client.subscribe("/cell/feeder_1/speed")
        payloads = [CDR_LE + struct.pack("<d", value) for value in (0.0125, -3.5)]
        # the subscription reaches the server asynchronously: write until the first arrives
        assert client.wait_for(
            lambda: sink.write("/cell/feeder_1/speed", payloads[0], 1_000) or client.frames, 10.0
        )
        sink.write("/cell/feeder_1/speed", payloads[1], 2_000_000_123)
        assert client.wait_for(lambda: client.frames[-1].payload == payloads[1], 10.0)
        last = client.frames[-1]
        assert last.log_time_ns == 2_000_000_123
        assert {f.payload for f in client.payloads("/cell/feeder_1/speed")} <= set(payloads)
        assert decode(channel, last.payload).data == -3.5  # type: ignore[attr-defined]


def test_a_nested_type_carries_its_dependencies_in_the_schema(sink: FoxgloveSink) -> None:
    sink.add_topic("/imu", "sensor_msgs/msg/Imu")
    with FoxgloveClient(sink.url) as client:
        assert client.wait_for(lambda: "/imu" in client.channels, 10.0)
        schema = str(client.channels["/imu"]["schema"])
        for dependency in ("MSG: std_msgs/Header", "MSG: geometry_msgs/Vector3"):
            assert dependency in schema


def test_an_unknown_type_or_a_second_channel_is_refused_by_name(sink: FoxgloveSink) -> None:
    with pytest.raises(UnknownTypeError, match="no_such_pkg/msg/Nothing"):
        sink.add_topic("/x", "no_such_pkg/msg/Nothing")
    sink.add_topic("/x", "std_msgs/msg/Float64")
    with pytest.raises(ValueError, match="topic /x is already served"):
        sink.add_topic("/x", "std_msgs/msg/Float64")
    assert sink.topics == ["/x"]


def test_a_taken_port_is_refused_with_the_port(sink: FoxgloveSink) -> None:
    with pytest.raises(LiveViewError, match=f"127.0.0.1:{sink.port}: .*in use"):
        FoxgloveSink(port=sink.port)


def test_a_closed_views_port_is_free_at_once() -> None:
    # foxglove-sdk's stop returns before its listener closes: a connection right after it was
    # accepted and dropped (CI), and a server started again on the port could find it taken
    first = FoxgloveSink(port=0)
    port = first.port
    first.close()
    for _ in range(50):
        sink = FoxgloveSink(port=port)  # the port closed just before: free
        sink.add_topic("/x", "std_msgs/msg/Float64")
        sink.close()
        with pytest.raises(ConnectionRefusedError):
            socket.create_connection((LOCALHOST, port), timeout=2.0).close()


def test_close_stops_the_server_and_may_be_repeated() -> None:
    served = FoxgloveSink(port=0)
    served.add_topic("/x", "std_msgs/msg/Float64")
    served.close()
    served.close()
    assert served.topics == []
    with pytest.raises(ConnectionRefusedError):
        FoxgloveClient(served.url)
