"""The drive interface's speed readings for resonance tracking (part of the node).

``tracking.feedback_topic`` carries the estimator's ``VehicleEstimate`` (read only with a
``mean_speed_confidence`` of at least ``tracking.min_confidence``: an estimate without enough
information is no reading) or the speed monitor's ``SpeedStatus``. Each reading goes to the
tracked control (:class:`~feeder_ros.drive.tracked_control.TrackedControl`, stamped with the
message's time, or the node's now for an unstamped one) and its speed to the part feeding. A
reading stamped more than ``FUTURE_STAMP_TOLERANCE_S`` ahead of the node's clock is ignored by
the tracker (it would keep tracking ACTIVE with no fresh reading); it is logged here, with the
likely cause.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from feeder_ros.drive.resonance_tracker import FUTURE_STAMP_TOLERANCE_S
from feeder_ros.drive.tracked_control import TrackedControl
from feeder_ros.msg import SpeedStatus, VehicleEstimate
from feeder_ros.nodes.ros_time import clock_seconds, stamp_seconds

__all__ = ["FEEDBACK_QOS", "TrackingFeedback"]

FEEDBACK_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


class TrackingFeedback:
    """The subscription to ``values["tracking.feedback_topic"]`` of ``values["tracking.
    feedback_type"]`` ("vehicle_estimate" or "speed_status"), made at configure on ``node``
    (``values``: the node's parameter values, read as they change); ``on_speed`` gets every
    reading's speed [m/s]; :meth:`close` at teardown."""

    def __init__(
        self,
        node: Node,
        tracked: TrackedControl,
        values: dict[str, Any],
        on_speed: Callable[[float], None],
    ) -> None:
        self._node = node
        self._tracked = tracked
        self._values = values
        self._on_speed = on_speed
        topic = values["tracking.feedback_topic"]
        if values["tracking.feedback_type"] == "vehicle_estimate":
            self._subscription: Any = node.create_subscription(
                VehicleEstimate, topic, self._on_estimate, FEEDBACK_QOS
            )
        else:
            self._subscription = node.create_subscription(
                SpeedStatus, topic, self._on_speed_status, FEEDBACK_QOS
            )

    def close(self) -> None:
        if self._subscription is not None:
            self._node.destroy_subscription(self._subscription)
            self._subscription = None

    def _on_estimate(self, message: VehicleEstimate) -> None:
        if not message.mean_speed_confidence >= self._values["tracking.min_confidence"]:
            return  # an estimate without enough information is no reading
        self._reading(message.header.stamp, message.mean_speed_mps, "estimate")

    def _on_speed_status(self, message: SpeedStatus) -> None:
        self._reading(message.header.stamp, message.estimated_speed_mps, "speed_status")

    def _reading(self, stamp: Any, speed_mps: float, topic: str) -> None:
        self._on_speed(speed_mps)
        now = clock_seconds(self._node.get_clock())
        t_s = stamp_seconds(stamp) or now
        if t_s > now + FUTURE_STAMP_TOLERANCE_S and math.isfinite(speed_mps):
            self._node.get_logger().warning(
                f"{topic} stamped {t_s:.3f} s, {t_s - now:.3g} s ahead of this node's clock "
                f"(over {FUTURE_STAMP_TOLERANCE_S:g} s): ignored by resonance tracking; do both "
                "nodes use the same clock (use_sim_time)?",
                throttle_duration_sec=5.0,
            )
        self._tracked.feedback(t_s, speed_mps)
