"""A one-minute feeder run written from code, with the cell's view of it (``speed/status``,
``drive/state``) and a drive fault: every headline figure of its report is known by hand.

Timeline (seconds from the start; stamps from ``T0``, a wall-clock time):

* drive commands: 30 Hz / 20 N at 0, 40 Hz / 20 N at 20, off at 30 (the fault), 40 Hz / 20 N at
  33, off at 40;
* drive state at 10 Hz, 0.0-60.0 s: ramping for the first second, running until 30, FAULT
  ("heartbeat lost: none for 2.00 s") 30-33, running 33-40, idle after: the drive is on 37 s;
* speed status at 2 Hz, 0.0-60.0 s: target 10 mm/s until 20, 8 mm/s until 40, none after; the
  monitor says "at target" (level OK) during 5-20, 25-30 and 35-40 s: 25 s of the 37 s driven
  with a target;
* a part leaves at every odd second while the drive runs (not during the fault): 19 parts.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.serialization import serialize_message

from feeder_ros.bag import BagWriter
from feeder_ros.msg import DriveCommand, DriveState, PartExit, SpeedStatus

T0 = 1_750_000_000_000_000_000  # 2025-06-15 15:06:40 UTC
S = 1_000_000_000
COMMANDS = [(0.0, 30.0, 20.0), (20.0, 40.0, 20.0), (30.0, 40.0, 0.0), (33.0, 40.0, 20.0),
            (40.0, 40.0, 0.0)]  # fmt: skip
FAULT = (30.0, 33.0, "heartbeat lost: none for 2.00 s")
AT_TARGET = [(5.0, 20.0), (25.0, 30.0), (35.0, 40.0)]
EXPECTED = {"run_s": 60.0, "driving_s": 37.0, "target_s": 37.0, "at_target_s": 25.0, "parts": 19}


def _stamped(message: Any, t_s: float) -> bytes:
    t_ns = T0 + round(t_s * S)
    message.header.stamp.sec = t_ns // S
    message.header.stamp.nanosec = t_ns % S
    return bytes(serialize_message(message))


def _drive_state(t: float) -> int:
    if FAULT[0] <= t < FAULT[1]:
        return DriveState.STATE_FAULT
    if t < 1.0:
        return DriveState.STATE_RAMPING
    return DriveState.STATE_RUNNING if t < 40.0 else DriveState.STATE_IDLE


def _target(t: float) -> float:
    return 0.010 if t < 20.0 else 0.008 if t < 40.0 else math.nan


def _diagnostics(ns: str, t: float) -> DiagnosticArray:
    """The drive's status (ERROR during the fault) and the estimator's part model, whose long
    refusal (as the real node words it) must wrap within the report's page."""
    array = DiagnosticArray()
    fault = FAULT[0] <= t < FAULT[1]
    array.status = [
        DiagnosticStatus(
            level=DiagnosticStatus.ERROR if fault else DiagnosticStatus.OK,
            name=f"{ns}/drive_interface: drive",
            message=f"fault: {FAULT[2]} (timeout 2 s)" if fault else "running",
        ),
        DiagnosticStatus(
            level=DiagnosticStatus.WARN if t >= 10 else DiagnosticStatus.OK,
            name=f"{ns}/vehicle_estimator: part model",
            message="refused: transit 1750000008.398-1750000015.411 s not used: the carrier was "
            "not steady at one drive setting for all of it (steady since 1750000009.434 s); "
            f"calibration file {ns}/very/long/path/without/any/space/calibration_part_model.yaml"
            if t >= 10
            else "nominal part (no measurement yet)",
        ),
    ]
    return array


def write_run_bag(path: Path, ns: str = "/line_1") -> None:
    with BagWriter(path) as w:
        topics = {
            "cmd": (f"{ns}/drive/command", "feeder_ros/msg/DriveCommand"),
            "state": (f"{ns}/drive/state", "feeder_ros/msg/DriveState"),
            "speed": (f"{ns}/speed/status", "feeder_ros/msg/SpeedStatus"),
            "exit": (f"{ns}/parts/exit", "feeder_ros/msg/PartExit"),
            "diag": ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        }
        for name, type_name in topics.values():
            w.add_topic(name, type_name)
        events: list[tuple[float, str, Any]] = []
        for t, f, amplitude in COMMANDS:
            command = DriveCommand(enabled=amplitude > 0, frequency_hz=f, amplitude_n=amplitude)
            events.append((t, "cmd", command))
        for k in range(601):
            t = k / 10
            state = _drive_state(t)
            message = DriveState(state=state, frequency_hz=30.0 if t < 20 else 40.0)
            message.amplitude_percent = 60.0 if state in (1, 2) else 0.0
            message.fault_reason = FAULT[2] if state == DriveState.STATE_FAULT else ""
            events.append((t, "state", message))
        for k in range(121):
            t = k / 2
            at_target = any(lo <= t < hi for lo, hi in AT_TARGET)
            target = _target(t)
            status = SpeedStatus(target_speed_mps=target, feed_rate_ppm=30.0)
            status.estimated_speed_mps = target if at_target else 0.5 * (target or 0.0)
            status.estimated_speed_uncertainty_mps = 0.0002
            status.transit_speed_mps = math.nan
            status.level = SpeedStatus.LEVEL_OK if at_target or t >= 40 else SpeedStatus.LEVEL_WARN
            status.message = "at target (x)" if at_target else "idle" if t >= 40 else "settling"
            events.append((t, "speed", status))
        for second in range(61):
            events.append((float(second), "diag", _diagnostics(ns, float(second))))
        fed = 0
        for k in range(1, 40, 2):
            if _drive_state(float(k)) == DriveState.STATE_RUNNING:
                fed += 1
                events.append((float(k), "exit", PartExit(part_id=fed, parts_out_total=fed)))
        assert fed == EXPECTED["parts"]
        for t, key, message in sorted(events, key=lambda e: e[0]):
            w.write(topics[key][0], _stamped(message, t), T0 + round(t * S) + 1000)
