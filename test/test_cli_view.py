"""``feeder view`` as a real process: it serves a running ``platform_simulator`` to a plain
WebSocket client, which sees the feeder's topics advertised with their ros2msg schemas and
receives messages that decode (rclpy) to exactly what a probe node received on the same topic."""

from __future__ import annotations

import re
import socket
import sys
from pathlib import Path
from typing import Any

import pytest
from foxglove_client import FoxgloveClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from ros_test_tools import probe_node, running, wait_until
from sensor_msgs.msg import Imu
from simulator_process import drive, manual_cell_file, simulator

from feeder_ros.bag.schemas import ros2msg_schema
from feeder_ros.msg import CarrierState, DriveCommand
from feeder_ros.nodes.platform_simulator_parameters import NODE_DEFAULTS

FEEDER = str(Path(sys.executable).parent / "feeder")
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
CONFIG = Path(__file__).resolve().parents[1] / "config"
URL = re.compile(r"serving the live view on (ws://127\.0\.0\.1:\d+)")


def stamp_ns(message: Any) -> int:
    return int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec)


def test_view_serves_a_running_simulator(tmp_path: Path) -> None:
    ns = "/view_cli"
    state_topic, imu_topic = f"{ns}/carrier/state", f"{ns}/imu"
    with simulator(ns), probe_node() as node:
        states: list[CarrierState] = []
        node.create_subscription(CarrierState, state_topic, states.append, RELIABLE)
        node.create_timer(0.05, drive(node, ns, 31.0, 40.0))
        assert wait_until(lambda: bool(states) and states[-1].drive_amplitude_n == 40.0, 20)
        with running([FEEDER, "view", "--namespace", ns, "--port", "0"]) as view:
            assert wait_until(lambda: URL.search(view.output()) is not None, 30), view.output()
            url = URL.search(view.output()).group(1)  # type: ignore[union-attr]
            with FoxgloveClient(url) as client:
                wanted = {state_topic, imu_topic, f"{ns}/parts/state", "/diagnostics"}
                assert client.wait_for(lambda: wanted <= set(client.channels), 30), client.channels
                assert all(t.startswith(ns + "/") or t == "/diagnostics" for t in client.channels)
                channel = client.channels[state_topic]
                assert (channel["schemaName"], channel["encoding"]) == (
                    "feeder_ros/msg/CarrierState",
                    "cdr",
                )
                assert channel["schema"] == ros2msg_schema("feeder_ros/msg/CarrierState")
                client.subscribe(state_topic)
                client.subscribe(imu_topic)
                assert client.wait_for(
                    lambda: (
                        len(client.payloads(state_topic)) >= 250
                        and len(client.payloads(imu_topic)) >= 100
                    ),
                    30,
                )
            # the probe holds every state the view sent once it has the newest one
            served = [
                deserialize_message(f.payload, CarrierState) for f in client.payloads(state_topic)
            ]
            newest = max(stamp_ns(m) for m in served)
            assert wait_until(lambda: stamp_ns(states[-1]) >= newest, 20)
    assert view.returncode == 0, view.output()
    assert "stopped by signal" in view.output()

    probe = {stamp_ns(m): m for m in states}
    stamps = [stamp_ns(m) for m in served]
    assert stamps == sorted(stamps)
    assert len(set(stamps)) == len(stamps)
    for message in served:
        received = probe[stamp_ns(message)]
        for name in ("displacement_m", "velocity_mps", "acceleration_mps2", "drive_frequency_hz"):
            assert getattr(message, name) == getattr(received, name)
    assert {m.drive_amplitude_n for m in served} == {40.0}
    assert {m.drive_frequency_hz for m in served} == {31.0}
    # log times: the view's clock at reception, after the message's own stamp
    log_times = [f.log_time_ns for f in client.payloads(state_topic)]
    assert log_times == sorted(log_times)
    assert all(
        0 <= log - stamp < 5_000_000_000 for log, stamp in zip(log_times, stamps, strict=True)
    )
    imu = [deserialize_message(f.payload, Imu) for f in client.payloads(imu_topic)]
    assert {m.header.frame_id for m in imu} == {NODE_DEFAULTS["imu_frame_id"]}
    accelerations = [m.linear_acceleration.x for m in imu]
    assert max(accelerations) - min(accelerations) > 1.0  # the carrier vibrates under 40 N


def test_view_on_a_taken_port_is_refused_with_the_port() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with running([FEEDER, "view", "--port", str(port), "--duration", "5"]) as view:
            assert wait_until(lambda: view.poll() is not None, 30)
    assert view.returncode == 2
    assert f"feeder view: error: cannot serve the live view on 127.0.0.1:{port}" in view.output()


def _manual_cell(tmp_path: Path) -> Path:
    """Two simulated feeders, each driven at 20 Hz, 40 N by its manual_drive node."""
    namespaces = ["/view_cell/feeder_a", "/view_cell/feeder_b"]
    return manual_cell_file(tmp_path / "cell.yaml", "view_cell", namespaces)


@pytest.mark.parametrize("composed", [False, True], ids=["processes", "composed"])
def test_cell_with_foxglove_serves_every_feeder(tmp_path: Path, composed: bool) -> None:
    command = [FEEDER, "cell", "--config", str(_manual_cell(tmp_path)), "--foxglove", "0"]
    with running(command + (["--composed"] if composed else [])) as cell:
        assert wait_until(lambda: URL.search(cell.output()) is not None, 60), cell.output()
        url = URL.search(cell.output()).group(1)  # type: ignore[union-attr]
        with FoxgloveClient(url) as client:
            commands = [f"/view_cell/feeder_{x}/drive/command" for x in "ab"]
            assert client.wait_for(lambda: set(commands) <= set(client.channels), 60)
            for topic in commands:
                assert client.channels[topic]["schemaName"] == "feeder_ros/msg/DriveCommand"
                client.subscribe(topic)
            assert client.wait_for(lambda: all(len(client.payloads(t)) >= 5 for t in commands), 30)
            for topic in commands:
                for frame in client.payloads(topic):
                    message = deserialize_message(frame.payload, DriveCommand)
                    assert (message.frequency_hz, message.amplitude_n) == (20.0, 40.0)
    assert cell.returncode == 0, cell.output()


def test_cell_stops_when_its_live_view_cannot_start() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cell_file = CONFIG / "cell.yaml"
        command = [FEEDER, "cell", "--config", str(cell_file), "--foxglove", str(port)]
        with running(command) as cell:
            assert wait_until(lambda: cell.poll() is not None, 60), cell.output()
    assert cell.returncode == 1
    assert f"cannot serve the live view on 127.0.0.1:{port}" in cell.output()
    assert "[cell] live view exited with 2: stopping the cell" in cell.output()
