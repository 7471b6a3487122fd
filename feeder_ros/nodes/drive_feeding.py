"""The drive interface's part feeding: track level control and the ``feed_parts`` action.

Both read the part-present sensors (``parts/sensor_events``) and act through the
:class:`~feeder_ros.drive.controller.DriveController`; their decisions are made by the ROS-free
cores :mod:`feeder_ros.drive.level_control` and :mod:`feeder_ros.drive.part_feed`.

- **Level control** (``level.mode``): a full track puts a hold on the controller (the output ramps
  to zero, ``drive/state`` says PAUSED with the reason) and a cleared track releases it; a sensor
  time-out latches a drive fault.
- **feed_parts** (``action/FeedParts.action``): one goal at a time. Every goal is accepted by the
  action server so that a refused one can say why: it ends at once with ``OUTCOME_REFUSED`` and the
  reason, and nothing changes (a second goal while one runs is refused this way; the running goal
  goes on). A goal starts the drive at its stored set point (``set_drive`` or ``set_target_speed``
  first); when it ends, for whatever reason, the output ramps to zero and the result is sent once
  the output is off, so a result means the feeder has stopped. The heartbeat watchdog still
  applies: a lost heartbeat faults the drive and the goal ends FAULTED.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from rclpy.action.server import ActionServer, CancelResponse, GoalResponse
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future

from feeder_ros.action import FeedParts
from feeder_ros.drive.controller import DriveController, DriveState
from feeder_ros.drive.level_control import LevelControl, LevelDecision, LevelMode, LevelState
from feeder_ros.drive.part_feed import (
    PART_ID_UNKNOWN,
    FeedMode,
    FeedOutcome,
    FeedProgress,
    FeedRequest,
    PartFeed,
    request_refusal,
)
from feeder_ros.msg import PartSensorEvent
from feeder_ros.nodes.ros_time import clock_seconds, stamp_seconds

if TYPE_CHECKING:
    from rclpy.node import Node

    from feeder_ros.drive.backend import DriveOutput
    from feeder_ros.msg import DriveState as DriveStateMsg

__all__ = ["OUTCOME_REFUSED", "SENSOR_QOS", "Feeding"]

#: part-present sensor edges: every edge counts (a lost falling edge is a part not counted)
SENSOR_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
OUTCOME_REFUSED = 6  # FeedParts.Result.OUTCOME_REFUSED
_LEVEL_HOLD = "level"


class _Goal:
    """A running feed_parts goal: its core, its action handle, and the future its execution
    waits on (set once the goal has ended and the output is off)."""

    def __init__(self, feed: PartFeed, handle: Any) -> None:
        self.feed = feed
        self.handle = handle
        self.future: Any = Future()  # Future[FeedProgress] (generic on Kilted only)
        self.final: FeedProgress | None = None
        self.feedback_t = -math.inf
        self.feedback_delivered = -1


class Feeding:
    """Level control and feed_parts for ``node`` (a DriveInterface); ``speed_mps`` is the last
    part speed of the node's speed feedback (:meth:`set_speed`; NaN when none)."""

    def __init__(self, node: Node, values: dict[str, Any]) -> None:
        self._node = node
        self._values = values
        self._controller: DriveController | None = None
        self._level: LevelControl | None = None
        self._decision: LevelDecision | None = None
        self._sensor_sub: Any = None
        self._covered: dict[int, bool] = {}
        self._rise: dict[int, tuple[float, int]] = {}  # per sensor: its last rising edge, part
        self._goal: _Goal | None = None
        self.last_delivered = 0
        self.speed_mps = math.nan
        self._server = ActionServer(
            node,
            FeedParts,
            "feed_parts",
            execute_callback=self._execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=self._on_cancel,
        )

    # -- lifecycle ---------------------------------------------------------------------------------
    def set_speed(self, speed_mps: float) -> None:
        self.speed_mps = speed_mps

    def configure(self, controller: DriveController, level: LevelControl) -> None:
        self._controller = controller
        self._level = level
        self._decision = None
        self._covered = {}
        self._rise = {}
        self._sensor_sub = self._node.create_subscription(
            PartSensorEvent, "parts/sensor_events", self._on_sensor_event, SENSOR_QOS
        )

    def teardown(self, now_s: float) -> None:
        goal = self._goal
        if goal is not None:
            self._finish(goal, goal.feed.abort(now_s, FeedOutcome.ABORTED, "drive shut down"))
        if self._sensor_sub is not None:
            self._node.destroy_subscription(self._sensor_sub)
            self._sensor_sub = None
        self._controller = None
        self._level = None

    def destroy(self) -> None:
        self._server.destroy()

    # -- inputs ------------------------------------------------------------------------------------
    def _on_sensor_event(self, message: PartSensorEvent) -> None:
        index, present = int(message.sensor_index), bool(message.present)
        count = int(self._values["part_sensor_count"])
        if index >= count:
            self._node.get_logger().warning(
                f"parts/sensor_events: sensor_index={index} ignored: part_sensor_count is "
                f"{count} (sensors 0..{count - 1})",
                throttle_duration_sec=5.0,
            )
            return
        t_s = stamp_seconds(message.header.stamp)
        if not math.isfinite(t_s) or t_s <= 0.0:
            return
        # touching parts give the next part's rising edge and the last one's falling edge at one
        # instant, in either order: a light barrier stays dark, so such a falling edge is no edge
        part = int(message.part_id)
        covered = present
        if present:
            self._rise[index] = (t_s, part)
        else:
            rise_t, rise_part = self._rise.get(index, (math.nan, PART_ID_UNKNOWN))
            covered = abs(t_s - rise_t) < 1e-6 and rise_part != part
        if self._level is not None and self._covered.get(index) != covered:
            self._level.edge(t_s, index, covered)
        self._covered[index] = covered
        if self._goal is not None:
            self._goal.feed.edge(t_s, index, int(message.part_id), present)

    def reset_fault(self, now_s: float) -> None:
        if self._level is not None:
            self._level.reset(now_s)

    # -- the loop (before the controller's tick) -----------------------------------------------
    def tick(self, controller: DriveController, now_s: float, last: DriveOutput) -> None:
        feeding = last.enabled and controller.running and not controller.paused
        if self._level is not None:
            self._decision = self._level.update(now_s, feeding)
            self._apply_level(controller, now_s, self._decision)
        goal = self._goal
        if goal is None:
            return
        if goal.final is None:
            progress = self._progress(goal, controller, now_s, feeding)
            if progress.done:
                goal.final = progress
                controller.stop(now_s)
                self._node.get_logger().info(f"feed_parts: {progress.reason}; ramping to zero")
            else:
                self._feedback(goal, progress, controller, now_s)
        if (
            goal.final is not None
            and not last.enabled
            and controller.state is not DriveState.RAMPING
        ):
            self._finish(goal, goal.final)

    def _apply_level(
        self, controller: DriveController, now_s: float, decision: LevelDecision
    ) -> None:
        if decision.fault:
            controller.fault(now_s, f"level control: {decision.fault}")
        if decision.state is LevelState.FULL:
            controller.hold(now_s, _LEVEL_HOLD, decision.reason)
        else:
            controller.release(now_s, _LEVEL_HOLD)

    def _progress(
        self, goal: _Goal, controller: DriveController, now_s: float, feeding: bool
    ) -> FeedProgress:
        feed = goal.feed
        if goal.handle.is_cancel_requested:
            return feed.cancel(now_s)
        if controller.latched is DriveState.ESTOP:
            return feed.abort(
                now_s, FeedOutcome.ESTOPPED, f"emergency stop: {controller.fault_reason}"
            )
        if controller.latched is DriveState.FAULT:
            return feed.abort(now_s, FeedOutcome.FAULTED, f"drive fault: {controller.fault_reason}")
        if not controller.active:
            return feed.abort(now_s, FeedOutcome.ABORTED, "drive interface deactivated")
        if not controller.running:
            return feed.abort(now_s, FeedOutcome.ABORTED, "stopped by a stop request")
        return feed.update(now_s, feeding)

    def _feedback(
        self, goal: _Goal, progress: FeedProgress, controller: DriveController, now_s: float
    ) -> None:
        period = float(self._values["feed.feedback_period_s"])
        if progress.delivered == goal.feedback_delivered and now_s - goal.feedback_t < period:
            return
        goal.feedback_t, goal.feedback_delivered = now_s, progress.delivered
        self.last_delivered = progress.delivered
        feedback = FeedParts.Feedback()
        feedback.parts_delivered = progress.delivered
        feedback.speed_mps = self.speed_mps
        feedback.elapsed_s = progress.elapsed_s
        feedback.paused = controller.paused
        goal.handle.publish_feedback(feedback)

    def _finish(self, goal: _Goal, progress: FeedProgress) -> None:
        self._goal = None
        self.last_delivered = progress.delivered
        if not goal.future.done():
            goal.future.set_result(progress)

    # -- the action --------------------------------------------------------------------------------
    def _on_cancel(self, handle: Any) -> CancelResponse:
        goal = self._goal
        if goal is None or goal.handle.goal_id != handle.goal_id or goal.final is not None:
            return CancelResponse.REJECT
        return CancelResponse.ACCEPT

    def _refusal(self, request: Any, now_s: float) -> str:
        controller = self._controller
        if controller is None:
            return "drive interface not configured"
        if self._goal is not None:
            return (
                f"another feed_parts goal is running ({self._describe(self._goal.feed.request)}, "
                f"{self.last_delivered} delivered so far): cancel it first"
            )
        timeout = float(request.starvation_timeout_s) or float(
            self._values["feed.starvation_timeout_s"]
        )
        return request_refusal(
            int(request.mode),
            int(request.part_count),
            int(request.sensor_index),
            timeout,
            int(self._values["part_sensor_count"]),
        )

    async def _execute(self, handle: Any) -> Any:
        now_s = clock_seconds(self._node.get_clock())
        request = handle.request
        refusal = self._refusal(request, now_s)
        controller = self._controller
        if refusal or controller is None:
            return self._refused(handle, refusal)
        timeout = float(request.starvation_timeout_s) or float(
            self._values["feed.starvation_timeout_s"]
        )
        feed_request = FeedRequest(
            FeedMode(int(request.mode)), int(request.part_count), int(request.sensor_index), timeout
        )
        feed = PartFeed(feed_request, now_s, self._covered.get(feed_request.sensor_index))
        early = feed.update(now_s, False)
        if not early.done:
            answer = controller.start(now_s)
            if not answer.success:
                return self._refused(handle, answer.message)
            self._node.get_logger().info(
                f"feed_parts: {self._describe(feed_request)}; {answer.message}"
            )
        goal = _Goal(feed, handle)
        if early.done:
            goal.final = early
            goal.future.set_result(early)
        else:
            self._goal = goal
        progress: FeedProgress = await goal.future
        return self._result(handle, progress)

    @staticmethod
    def _describe(request: FeedRequest) -> str:
        if request.mode is FeedMode.COUNT:
            return f"{request.part_count} parts past sensor {request.sensor_index}"
        return f"until a part is at sensor {request.sensor_index}"

    def _refused(self, handle: Any, reason: str) -> Any:
        self._node.get_logger().warning(f"feed_parts goal refused: {reason}")
        handle.abort()
        result = FeedParts.Result()
        result.outcome = OUTCOME_REFUSED
        result.reason = reason
        result.time_per_part_s = math.nan
        return result

    def _result(self, handle: Any, progress: FeedProgress) -> Any:
        result = FeedParts.Result()
        outcome = progress.outcome if progress.outcome is not None else FeedOutcome.ABORTED
        result.outcome = int(outcome)
        result.reason = progress.reason
        result.parts_delivered = progress.delivered
        result.elapsed_s = progress.elapsed_s
        result.time_per_part_s = progress.time_per_part_s
        if outcome is FeedOutcome.SUCCEEDED:
            handle.succeed()
        elif outcome is FeedOutcome.CANCELED and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result

    # -- what the node reports ---------------------------------------------------------------------
    def fill_state(self, message: DriveStateMsg, controller: DriveController) -> None:
        decision = self._decision
        message.level_state = int(decision.state) if decision is not None else 0
        message.pause_reason = controller.hold_reason if controller.paused else ""
        message.level_sensors = [
            -1 if seen is None else int(seen) for seen in (decision.sensors if decision else ())
        ]
        message.feed_active = self._goal is not None
        message.feed_parts_delivered = self.last_delivered

    def diagnostics(self) -> dict[str, str]:
        values: dict[str, str] = {}
        level = self._level
        if level is not None and level.settings.mode is not LevelMode.OFF:
            decision = self._decision
            values["level control"] = (
                decision.state.name.lower() if decision is not None else "starting"
            )
            if decision is not None and decision.reason:
                values["level reason"] = decision.reason
        goal = self._goal
        values["feed_parts"] = (
            f"running: {self._describe(goal.feed.request)}, {self.last_delivered} delivered"
            if goal is not None
            else f"idle (last goal delivered {self.last_delivered})"
        )
        return values
