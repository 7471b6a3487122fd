"""The installed ``platform_simulator`` as a process in a namespace, and a probe's drive command,
for the command-line tests that record or view a running feeder."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from rclpy.node import Node
from ros_test_tools import running

from feeder_ros.msg import DriveCommand

SIMULATOR = str(Path(sys.executable).parent / "platform_simulator")


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
