"""A simulator that cannot keep up with the wall clock says so and still obeys its commander.

Paced by the wall clock and given more work than it can do in real time (a 20 kHz accelerometer
published message by message, 10,000 parts' states at 1 kHz), it falls behind: a drive command
stamped by the commander's (wall) clock is then ahead of the simulation clock only because of the
simulator's own lag. It must be applied at once, not dropped as "from the future", and the lag
must be an ERROR with the achieved real-time factor, not a quiet WARN.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ros_test_tools import probe_node, running, wait_until

from feeder_ros.msg import DriveCommand

SIMULATOR = str(Path(sys.executable).parent / "platform_simulator")


def test_a_lagging_simulator_applies_commands_now_and_raises_error() -> None:
    ns = "/sim_lagging"
    command = [
        SIMULATOR, "--ros-args", "-r", f"__ns:={ns}",
        "-p", "imu_rate_hz:=20000.0", "-p", "state_rate_hz:=5000.0", "-p", "initial_parts:=10000",
        "-p", "part_spacing_m:=0.0", "-p", "parts_rate_hz:=1000.0",
        "-p", "max_lag_s:=0.5", "-p", "command_timeout_s:=5.0",
        # 10 ms steps: this load runs at about 0.01x real time, so a 50 ms step took 5 s and a
        # command waited for the step under way, then its diagnostics for the next: 20 s and more
        "-p", "max_step_s:=0.01",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        statuses: list[DiagnosticStatus] = []

        def on_diagnostics(message: DiagnosticArray) -> None:
            statuses.extend(
                s for s in message.status if s.name == f"{ns}/platform_simulator: simulation"
            )

        node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        publisher = node.create_publisher(DriveCommand, f"{ns}/drive/command", 10)

        def values() -> dict[str, str]:
            return {kv.key: kv.value for kv in statuses[-1].values} if statuses else {}

        def lagging() -> bool:
            return bool(statuses) and float(values()["lag_behind_schedule_s"]) > 1.5

        assert wait_until(lagging, 60.0), (process.poll(), statuses[-1:] if statuses else None)
        assert int.from_bytes(statuses[-1].level, "little") == 2
        assert statuses[-1].message.startswith("cannot keep up: ")
        assert "x real time (1x requested)" in statuses[-1].message
        achieved = float(values()["achieved_real_time_factor"])
        assert 0.0 < achieved < 0.9

        # the commander's clock (wall time) is ahead of the lagging simulation: applied now
        def drive() -> None:
            message = DriveCommand(enabled=True, frequency_hz=31.0, amplitude_n=40.0)
            message.header.stamp = node.get_clock().now().to_msg()
            publisher.publish(message)

        def driven() -> bool:
            drive()
            time.sleep(0.2)
            return float(values().get("drive_amplitude_n", "0")) == 40.0

        assert wait_until(driven, 20.0), values()
        assert int(values()["drive_commands_applied_late"]) >= 1
