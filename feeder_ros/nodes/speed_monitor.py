"""``speed_monitor``: part speed and feed rate against target, alarms, and ``/diagnostics``.

A thin shell over :class:`~feeder_ros.monitoring.speed_monitor.SpeedMonitor`: the estimator's
mean speed, part-present sensor edges, parts leaving the track and the drive interface's state go
in with the node clock's time of arrival (simulated time and bag replay work; a clock jumping back
restarts the windows); ``speed/status`` and ``/diagnostics`` come out.

Without a drive interface (e.g. a hand-held ``manual_drive``), the drive command tells whether
the feeder is driven and ``target_speed_mps`` gives the target.
"""

from __future__ import annotations

import math
import threading
import time
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from feeder_ros.monitoring.speed_monitor import MonitorConfig, SpeedMonitor
from feeder_ros.msg import (
    DriveCommand,
    DriveState,
    PartExit,
    PartSensorEvent,
    SpeedStatus,
    VehicleEstimate,
)
from feeder_ros.node_interfaces import NodeInterface, TopicSpec
from feeder_ros.nodes.diagnostics import diagnostic_array, diagnostic_status
from feeder_ros.nodes.ros_parameters import declare_parameters, validator
from feeder_ros.nodes.ros_time import clock_seconds, stamp_seconds
from feeder_ros.nodes.runner import run_node
from feeder_ros.nodes.stall_detector import StallDetector
from feeder_ros.physics.parameters import ParameterError, ParameterSpec

if TYPE_CHECKING:
    from feeder_ros.ros_compat import AnyParameter

_TIMES = (
    ("alarm_delay_s", "a speed error must last this long to raise under/overspeed"),
    ("stall_time_s", "driving with no part motion this long is a stall"),
    ("starvation_time_s", "driving and no part seen this long is starvation"),
    ("track_full_time_s", "a part-present sensor covered this long means the track is full"),
    (
        "sensor_timeout_s",
        "no estimate this long once they came (driving or not) is a sensor timeout (ERROR); "
        "estimates that keep coming below min_confidence this long while driving are a WARN",
    ),
    (
        "startup_timeout_s",
        "no first estimate this long after the drive starts is a sensor timeout (ERROR; WARN "
        "'waiting for the first speed estimate' until then)",
    ),
    ("feed_window_s", "window of the feed rate"),
)
PARAMETERS: dict[str, ParameterSpec] = {
    spec.name: spec
    for spec in (
        ParameterSpec(
            "target_speed_mps",
            float,
            "m/s",
            "target part speed when no drive interface gives one (NaN: none)",
            nan_allowed=True,
        ),
        ParameterSpec(
            "speed_tolerance",
            float,
            "1",
            "relative speed error that raises under/overspeed",
            minimum=0.0,
            maximum=10.0,
            exclusive_minimum=True,
        ),
        ParameterSpec(
            "clear_ratio", float, "1", "alarms clear below speed_tolerance * this", 0.0, 1.0
        ),
        ParameterSpec(
            "stall_speed_mps",
            float,
            "m/s",
            "part speed below which driving counts as stalled",
            minimum=0.0,
            exclusive_minimum=True,
        ),
        ParameterSpec(
            "min_confidence",
            float,
            "1",
            "estimates below this confidence give no speed (the estimator counts as alive); 0: "
            "judge by the uncertainty alone",
            0.0,
            1.0,
        ),
        ParameterSpec(
            "interval_sigma",
            float,
            "1",
            "the judged interval: the estimate +- this many standard uncertainties (2: 95 %); "
            "at target only when it lies wholly within the tolerance",
            minimum=0.0,
            maximum=10.0,
            exclusive_minimum=True,
        ),
        *(
            ParameterSpec(name, float, "s", text, minimum=0.0, exclusive_minimum=True)
            for name, text in _TIMES
        ),
        ParameterSpec("transit_first_sensor", int, "1", "index of the first timed sensor", 0, 1000),
        ParameterSpec(
            "transit_second_sensor", int, "1", "index of the second timed sensor", 0, 1000
        ),
        ParameterSpec(
            "transit_distance_m",
            float,
            "m",
            "distance between the two timed sensors",
            minimum=0.0,
            exclusive_minimum=True,
        ),
        ParameterSpec(
            "publish_rate_hz", float, "Hz", "status publish rate", 0.1, 100.0, read_only=True
        ),
    )
}
DEFAULTS: dict[str, Any] = {
    "target_speed_mps": math.nan,
    "speed_tolerance": 0.15,
    "clear_ratio": 0.6,
    "stall_speed_mps": 0.5e-3,
    "min_confidence": 0.0,
    "interval_sigma": 2.0,
    "alarm_delay_s": 2.0,
    "stall_time_s": 3.0,
    "starvation_time_s": 30.0,
    "track_full_time_s": 10.0,
    "sensor_timeout_s": 2.0,
    "startup_timeout_s": 10.0,
    "feed_window_s": 60.0,
    "transit_first_sensor": 0,
    "transit_second_sensor": 1,
    "transit_distance_m": 0.085,
    "publish_rate_hz": 2.0,
}
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)

INTERFACE = NodeInterface(
    executable="speed_monitor",
    node_name="speed_monitor",
    summary="compares part speed and feed rate with the target; stall, starvation, track-full",
    publishes=(
        TopicSpec(
            "speed/status",
            "feeder_ros/msg/SpeedStatus",
            "reliable, depth 10",
            "speeds, feed rate, level and alarm bits, at publish_rate_hz",
        ),
        TopicSpec(
            "/diagnostics",
            "diagnostic_msgs/msg/DiagnosticArray",
            "reliable, depth 10",
            "the same as a diagnostic status (OK/WARN/ERROR with key-values)",
        ),
    ),
    subscribes=(
        TopicSpec(
            "estimate", "feeder_ros/msg/VehicleEstimate", "reliable, depth 100", "mean part speed"
        ),
        TopicSpec(
            "parts/sensor_events",
            "feeder_ros/msg/PartSensorEvent",
            "reliable, depth 100",
            "part-present sensor edges (transit speed, starvation, track full)",
        ),
        TopicSpec("parts/exit", "feeder_ros/msg/PartExit", "reliable, depth 100", "feed count"),
        TopicSpec(
            "drive/state",
            "feeder_ros/msg/DriveState",
            "reliable, depth 100",
            "driving or not, and the target speed (from the drive interface)",
        ),
        TopicSpec(
            "drive/command",
            "feeder_ros/msg/DriveCommand",
            "reliable, depth 100",
            "driving or not, when no drive interface publishes its state",
        ),
    ),
    parameters=PARAMETERS,
)


def _config(values: dict[str, Any]) -> MonitorConfig:
    return MonitorConfig(
        speed_tolerance=values["speed_tolerance"],
        clear_ratio=values["clear_ratio"],
        alarm_delay_s=values["alarm_delay_s"],
        min_confidence=values["min_confidence"],
        interval_sigma=values["interval_sigma"],
        stall_speed_mps=values["stall_speed_mps"],
        stall_time_s=values["stall_time_s"],
        starvation_time_s=values["starvation_time_s"],
        track_full_time_s=values["track_full_time_s"],
        sensor_timeout_s=values["sensor_timeout_s"],
        startup_timeout_s=values["startup_timeout_s"],
        feed_window_s=values["feed_window_s"],
        transit_pair=(values["transit_first_sensor"], values["transit_second_sensor"]),
        transit_distance_m=values["transit_distance_m"],
    )


class SpeedMonitorNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(INTERFACE.node_name, **kwargs)
        self._values = declare_parameters(self, PARAMETERS.values(), DEFAULTS)
        _config(self._values)
        self.add_on_set_parameters_callback(
            validator(PARAMETERS, check_all=_config, current=lambda: self._values)
        )
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._lock = threading.Lock()
        self._monitor = SpeedMonitor(_config(self._values))
        self._has_drive_state = False
        self._status_pub = self.create_publisher(SpeedStatus, "speed/status", 10)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(VehicleEstimate, "estimate", self._on_estimate, RELIABLE)
        self.create_subscription(PartSensorEvent, "parts/sensor_events", self._on_edge, RELIABLE)
        self.create_subscription(PartExit, "parts/exit", self._on_exit, RELIABLE)
        self.create_subscription(DriveState, "drive/state", self._on_drive_state, RELIABLE)
        self.create_subscription(DriveCommand, "drive/command", self._on_command, RELIABLE)
        self.create_timer(1.0 / self._values["publish_rate_hz"], self._publish)
        # a tick late because this process stalled: the inputs sent meanwhile are still on their
        # way; silence counts from the end of the middleware's catch-up (not a false sensor
        # timeout)
        self._stalls = StallDetector(
            1.0 / self._values["publish_rate_hz"], start_s=time.monotonic()
        )

    def _now(self) -> float:
        return clock_seconds(self.get_clock())

    def _apply_parameters(self, parameters: list[AnyParameter]) -> None:
        for parameter in parameters:
            if parameter.name in PARAMETERS:
                self._values[parameter.name] = parameter.value
        with self._lock:  # new limits from now on; raised alarms and the history are kept
            self._monitor.reconfigure(_config(self._values))

    def _on_estimate(self, message: VehicleEstimate) -> None:
        with self._lock:
            self._monitor.on_estimate(
                self._now(),
                message.mean_speed_mps,
                message.mean_speed_confidence,
                message.mean_speed_uncertainty_mps,
            )

    def _on_edge(self, message: PartSensorEvent) -> None:
        part = None if message.part_id == PartSensorEvent.PART_ID_UNKNOWN else message.part_id
        stamp = message.header.stamp
        edge_t = stamp_seconds(stamp) if stamp.sec or stamp.nanosec else None
        with self._lock:
            self._monitor.on_sensor_edge(
                self._now(), message.sensor_index, part, message.present, edge_t
            )

    def _on_exit(self, message: PartExit) -> None:
        with self._lock:
            self._monitor.on_exit(self._now())

    def _on_drive_state(self, message: DriveState) -> None:
        driving = message.state in (DriveState.STATE_RUNNING, DriveState.STATE_RAMPING)
        target = (
            message.target_speed_mps if message.speed_mode else self._values["target_speed_mps"]
        )
        with self._lock:
            self._has_drive_state = True
            try:
                self._monitor.on_drive(
                    self._now(), driving and message.amplitude_percent > 0.0, target
                )
            except ParameterError as error:
                self.get_logger().warning(
                    f"ignoring drive/state message: {error}", throttle_duration_sec=5.0
                )

    def _on_command(self, message: DriveCommand) -> None:
        with self._lock:
            if self._has_drive_state:
                return  # the drive interface's state is the better source
            driving = message.enabled and message.amplitude_n > 0.0
            self._monitor.on_drive(self._now(), driving, self._values["target_speed_mps"])

    def _publish(self) -> None:
        resuming = self._stalls.resuming(time.monotonic())
        with self._lock:
            now = self._now()
            if resuming:
                # the catch-up runs on the wall clock, the monitor on the node clock (maybe a
                # faster simulation's): it listens from every tick within the catch-up
                self._monitor.resumed(now)
            status = self._monitor.evaluate(now)
        message = SpeedStatus()
        message.header.stamp = self.get_clock().now().to_msg()
        message.target_speed_mps = status.target_speed_mps
        message.estimated_speed_mps = status.estimated_speed_mps
        message.estimated_speed_uncertainty_mps = status.estimated_speed_uncertainty_mps
        message.transit_speed_mps = status.transit_speed_mps
        message.feed_rate_ppm = status.feed_rate_ppm
        message.level = status.level
        message.alarms = status.alarms
        message.message = status.message
        self._status_pub.publish(message)
        values = {
            "target_speed_mps": f"{status.target_speed_mps:.6g}",
            "estimated_speed_mps": f"{status.estimated_speed_mps:.6g}",
            "transit_speed_mps": f"{status.transit_speed_mps:.6g}",
            "feed_rate_ppm": f"{status.feed_rate_ppm:.3f}",
            "alarms": str(status.alarms),
            **status.details,
            **self._stalls.diagnostic_values(),
        }
        name = f"{self.get_fully_qualified_name()}: part speed"
        diagnostic = diagnostic_status(name, status.level, status.message, "feeder track", values)
        array = diagnostic_array(message.header.stamp, diagnostic)
        self._diagnostics_pub.publish(array)


NODE_CLASS = SpeedMonitorNode


def main(args: list[str] | None = None) -> int:
    return run_node(SpeedMonitorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
