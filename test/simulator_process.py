"""The installed ``platform_simulator`` as a process in a namespace, a probe's drive command, and
a cell description of manually driven simulated feeders, for the tests of commands that run,
record or view feeders."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import yaml
from rclpy.node import Node
from ros_test_tools import running

from feeder_ros.msg import DriveCommand

SIMULATOR = str(Path(sys.executable).parent / "platform_simulator")
CONFIG = Path(__file__).resolve().parents[1] / "config"


def manual_cell_file(path: Path, name: str, namespaces: Sequence[str]) -> Path:
    """Write a cell description to ``path``: in each namespace a simulated feeder (the realistic
    preset, IMU 200 Hz, state 50 Hz) driven at 20 Hz, 40 N by its ``manual_drive`` node."""
    nodes = {
        "platform_simulator": {
            "params_file": str(CONFIG / "platform_simulator.yaml"),
            "section": "platform_simulator_realistic",
            "parameters": {"imu_rate_hz": 200.0, "state_rate_hz": 50.0},
        },
        "manual_drive": {"parameters": {"frequency_hz": 20.0, "amplitude_n": 40.0}},
    }
    feeders = [{"namespace": ns, "nodes": nodes} for ns in namespaces]
    path.write_text(yaml.safe_dump({"cell": {"name": name, "feeders": feeders}}), "utf-8")
    return path


@contextmanager
def simulator(ns: str) -> Iterator[subprocess.Popen[str]]:
    command = [
        SIMULATOR, "--ros-args", "-r", f"__ns:={ns}",
        "-p", "state_rate_hz:=250.0", "-p", "imu_rate_hz:=250.0", "-p", "parts_rate_hz:=50.0",
        "-p", "damping_ns_per_m:=30.0",
        # no command watchdog: these tests are about recording or viewing, and on a loaded machine a
        # command may reach the simulator late (the watchdog has its own simulator test)
        "-p", "command_timeout_s:=0.0",
    ]  # fmt: skip
    with running(command) as process:
        yield process
    assert process.returncode == 0


def drive(node: Node, ns: str, frequency_hz: float, amplitude_n: float) -> Callable[[], None]:
    """A callback publishing the drive command, stamped now (a timer repeats it until the
    simulator has been discovered)."""
    publisher = node.create_publisher(DriveCommand, f"{ns}/drive/command", 10)

    def send() -> None:
        message = DriveCommand(enabled=True, frequency_hz=frequency_hz, amplitude_n=amplitude_n)
        message.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(message)

    return send
