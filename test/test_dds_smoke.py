"""Two real processes exchange a custom message over DDS, with every field checked."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ros_test_tools import running

VENV_BIN = Path(sys.executable).parent

RECEIVER = r"""
import json, sys
import rclpy
from feeder_ros.ros_compat import RosSession
from rclpy.qos import QoSProfile, ReliabilityPolicy
from feeder_ros.msg import DriveCommand

with RosSession():
    node = rclpy.create_node("smoke_receiver")
    received = []
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(DriveCommand, "/smoke/drive/command", received.append, qos)
    print("ready", flush=True)
    while not received:
        rclpy.spin_once(node, timeout_sec=0.2)
    m = received[0]
    print(json.dumps({
        "stamp": [m.header.stamp.sec, m.header.stamp.nanosec],
        "enabled": m.enabled, "frequency_hz": m.frequency_hz, "amplitude_n": m.amplitude_n,
        "amplitude_percent": m.amplitude_percent, "ramp_time_s": m.ramp_time_s,
    }), flush=True)
"""


def test_custom_message_crosses_processes() -> None:
    receiver = subprocess.Popen(
        [sys.executable, "-c", RECEIVER], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert receiver.stdout is not None
        assert receiver.stdout.readline().strip() == "ready"
        sender = [
            str(VENV_BIN / "manual_drive"),
            "--ros-args",
            "-r", "__ns:=/smoke",
            "-p", "enabled:=false",
            "-p", "frequency_hz:=47.25",
            "-p", "amplitude_n:=12.5",
            "-p", "amplitude_percent:=41.0",
            "-p", "ramp_time_s:=0.75",
            "-p", "rate_hz:=20.0",
        ]  # fmt: skip
        with running(sender):
            out, err = receiver.communicate(timeout=30)
    finally:
        if receiver.poll() is None:
            receiver.kill()
    assert receiver.returncode == 0, err
    values = json.loads(out.strip().splitlines()[-1])
    assert values["enabled"] is False
    assert values["frequency_hz"] == 47.25
    assert values["amplitude_n"] == 12.5
    assert values["amplitude_percent"] == 41.0
    assert values["ramp_time_s"] == 0.75
    assert values["stamp"][0] > 1_600_000_000  # stamped with the sender's clock
