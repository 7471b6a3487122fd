"""The drive interface's link to the platform simulator (its ``sim`` backend; part of the node).

Outputs go out on ``drive/command`` (reliable), stamped with the time the ramp value was computed
for. The simulator's ``parts/state`` is read only as its sign of life: silent for
``sim_feedback_timeout_s`` after it was heard, the simulator is lost (the backend's fault,
:class:`~feeder_ros.drive.backend.SimBackend`). Silence counts on the wall clock (a simulator
gone stops ``/clock`` too), and after a stall of this node's own (a control tick over half a
second late: a loaded machine, a composed cell's busy thread) from the end of the middleware's
catch-up (:class:`~feeder_ros.nodes.stall_detector.StallDetector`): the simulator's messages sent
meanwhile are still on their way.
"""

from __future__ import annotations

import time
from typing import Any

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time

from feeder_ros.drive.backend import DriveOutput, SimBackend
from feeder_ros.msg import DriveCommand, PartStateArray
from feeder_ros.nodes.stall_detector import StallDetector

__all__ = ["SimLink"]

COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: the simulator's parts/state, read only as a sign of life
SIM_FEEDBACK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)


class SimLink:
    """The publisher, the sign-of-life subscription and the :class:`SimBackend` over them, made
    at configure on ``node``; :meth:`tick` once per control tick, :meth:`close` at teardown."""

    def __init__(self, node: Node, control_period_s: float, feedback_timeout_s: float) -> None:
        self._node = node
        self._publisher: Any = node.create_publisher(DriveCommand, "drive/command", COMMAND_QOS)
        self._heard: float | None = None  # time.monotonic() of its last message
        self._stalls = StallDetector(control_period_s, start_s=time.monotonic())
        self._listening = time.monotonic()  # since this node listens (after its own stall)
        self._subscription: Any = node.create_subscription(
            PartStateArray, "parts/state", self._on_parts, SIM_FEEDBACK_QOS
        )
        self.backend = SimBackend(
            self._publish, self._publisher.get_subscription_count, self._age, feedback_timeout_s
        )

    @property
    def stalls(self) -> StallDetector:
        """This node's own stalls (for its diagnostics)."""
        return self._stalls

    def tick(self) -> None:
        """Once per control tick, before the backend's status is read."""
        if self._stalls.resuming(time.monotonic()):
            self._listening = time.monotonic()

    def close(self) -> None:
        """Stop listening; the last (disabled) command reaches the simulator before the writer
        goes away (destroying a reliable writer drops what readers have not acknowledged)."""
        node = self._node
        if self._subscription is not None:
            node.destroy_subscription(self._subscription)
            self._subscription = None
        if self._publisher is not None:
            if node.context.ok():
                self._publisher.wait_for_all_acked(Duration(seconds=1.0))
            node.destroy_publisher(self._publisher)
            self._publisher = None

    def _on_parts(self, message: PartStateArray) -> None:
        self._heard = time.monotonic()

    def _age(self) -> float | None:
        heard = self._heard
        if heard is None:
            return None
        return time.monotonic() - max(heard, self._listening)

    def _publish(self, output: DriveOutput) -> None:
        if self._publisher is None or not self._node.context.ok():
            return  # shutting down after Ctrl-C: the simulator takes a silent drive as a stop
        message = DriveCommand()
        # stamped with the time the ramp value was computed for, so that stamps and values agree
        message.header.stamp = Time(nanoseconds=round(output.time_s * 1e9)).to_msg()
        message.enabled = output.enabled
        message.frequency_hz = output.frequency_hz
        message.amplitude_percent = output.amplitude_percent
        message.amplitude_n = output.amplitude_n
        message.ramp_time_s = output.ramp_time_s
        self._publisher.publish(message)
