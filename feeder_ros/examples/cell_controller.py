"""An example cell controller: drives a feeder only through the suite's public ROS interface.

What a pick-and-place cell's PLC or orchestrator does with a feeder, as a small rclpy program:

1. bring the drive interface up (lifecycle configure + activate) and send a heartbeat; wait until
   the feeder's sensors are live (its estimator publishes: the accelerometer stream is up);
2. start the feeder and ask for a part speed (``set_target_speed``), then watch ``speed/status``
   until the speed monitor confirms the target (on a feeder that is not its model the estimator
   first calibrates its part model from the sensor transits, and the drive trims onto the target)
   and hold it for a while;
3. change the speed, the same way;
4. go silent for longer than the watchdog timeout (as a crashed controller would): the drive
   interface ramps the feeder down and reports a fault; come back, reset the fault, restart;
5. ask for parts as a robot cell does: the ``feed_parts`` action delivers a number of parts past
   a part-present sensor, with feedback, and stops the feeder (its result comes once the output
   is off);
6. stop.

Every step is printed with what the feeder answered; ``--timeline FILE`` writes the steps as JSON
(the demo uses it for its summary). Installed as the ``cell_controller`` executable; run it against
a running cell, e.g. ``feeder cell``:

    ros2 run feeder_ros cell_controller --namespace /demo_cell/feeder_1
    cell_controller --namespace /demo_cell/feeder_1     # in the project venv
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from pathlib import Path
from typing import Any

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.action.client import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from feeder_ros.action import FeedParts
from feeder_ros.msg import DriveState, SpeedStatus, VehicleEstimate
from feeder_ros.nodes.service_calls import call_service
from feeder_ros.ros_compat import RosSession
from feeder_ros.srv import SetTargetSpeed

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
STATE_NAMES = {0: "idle", 1: "ramping", 2: "running", 3: "fault", 4: "e-stop", 5: "paused"}
FEED_OUTCOMES = ("succeeded", "starved", "faulted", "e-stopped", "canceled", "aborted", "refused")


class CellController(Node):
    def __init__(self, namespace: str, **kwargs: Any) -> None:
        super().__init__("cell_controller", namespace=namespace, **kwargs)
        self.timeline: list[dict[str, Any]] = []
        self.heartbeat_on = True
        self.drive_state: DriveState | None = None
        self.speed_status: SpeedStatus | None = None
        self.estimates = 0
        self._heartbeat = self.create_publisher(Header, "heartbeat", RELIABLE)
        self.create_subscription(DriveState, "drive/state", self._on_drive_state, RELIABLE)
        self.create_subscription(SpeedStatus, "speed/status", self._on_speed_status, RELIABLE)
        self.create_subscription(VehicleEstimate, "estimate", self._on_estimate, RELIABLE)
        self.create_timer(0.2, self._beat)
        # kept for the node's life: destroying an action client while the executor thread spins
        # can leave that thread a dangling handle (RCLError in its wait set)
        self._feed_client: Any = ActionClient(self, FeedParts, "feed_parts")
        self._service_clients: dict[str, Any] = {}  # service name -> client, see call()
        self._start_time = time.monotonic()

    # -- inputs --------------------------------------------------------------------------------
    def _beat(self) -> None:
        if self.heartbeat_on:
            header = Header()
            header.stamp = self.get_clock().now().to_msg()
            header.frame_id = "cell_controller"
            self._heartbeat.publish(header)

    def _on_drive_state(self, message: DriveState) -> None:
        self.drive_state = message

    def _on_speed_status(self, message: SpeedStatus) -> None:
        self.speed_status = message

    def _on_estimate(self, message: VehicleEstimate) -> None:
        self.estimates += 1

    # -- helpers -------------------------------------------------------------------------------
    def log(self, step: str, **details: Any) -> None:
        elapsed = time.monotonic() - self._start_time
        entry = {"t_s": round(elapsed, 2), "wall_s": time.time(), "step": step, **details}
        self.timeline.append(entry)
        extra = ", ".join(f"{k}={v}" for k, v in details.items())
        print(f"[controller {elapsed:6.1f} s] {step}" + (f": {extra}" if extra else ""), flush=True)

    def call(
        self,
        service_type: Any,
        name: str,
        request: Any,
        timeout_s: float = 30.0,
        ask_again_s: float | None = None,
    ) -> Any:
        """Call a service and wait for its answer at most ``timeout_s``; one without an answer
        after ``ask_again_s`` is sent again (:func:`feeder_ros.nodes.service_calls.call_service`:
        only for requests that may run twice, such as get_state, ``start``/``stop``/
        ``reset_fault``, where the second finds the drive where the first left it; a lifecycle
        transition or ``set_target_speed``, which would restart the speed trim, is sent once).
        Clients are kept for the node's life."""
        client = self._service_clients.get(name)
        if client is None:
            client = self._service_clients[name] = self.create_client(service_type, name)

        def asking_again() -> None:
            self.log("no answer, asking again", service=name, after_s=ask_again_s)

        return call_service(client, request, timeout_s, ask_again_s, asking_again)

    def wait_for(self, what: str, predicate: Any, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.1)
        self.log(f"gave up waiting for {what}", timeout_s=timeout_s)
        return False

    def state_name(self) -> str:
        state = self.drive_state
        return STATE_NAMES.get(state.state, "?") if state is not None else "unknown"

    # -- the scenario --------------------------------------------------------------------------
    def bring_up(self) -> None:
        answer = self.call(
            GetState, "drive_interface/get_state", GetState.Request(), ask_again_s=5.0
        )
        label = answer.current_state.label
        self.log("drive interface lifecycle state", state=label)
        for transition, needed in (
            (Transition.TRANSITION_CONFIGURE, "unconfigured"),
            (Transition.TRANSITION_ACTIVATE, "inactive"),
        ):
            if label == needed:
                result = self.call(
                    ChangeState,
                    "drive_interface/change_state",
                    ChangeState.Request(transition=Transition(id=transition)),
                    timeout_s=120.0,  # configure computes the speed table (cached afterwards)
                )
                label = "inactive" if needed == "unconfigured" else "active"
                self.log(f"lifecycle -> {label}", success=result.success)

    def trigger(self, name: str) -> bool:
        answer = self.call(Trigger, name, Trigger.Request(), ask_again_s=5.0)
        self.log(name, success=answer.success, message=answer.message)
        return bool(answer.success)

    def start(self, wait_s: float = 10.0) -> bool:
        """``start``; while the drive interface has not heard our heartbeat yet (just after
        start-up the topic is still being discovered) it refuses, so ask again for a while."""
        deadline = time.monotonic() + wait_s
        while True:
            answer = self.call(Trigger, "start", Trigger.Request(), ask_again_s=5.0)
            unheard = not answer.success and "send heartbeats first" in answer.message
            if not unheard or time.monotonic() > deadline:
                self.log("start", success=answer.success, message=answer.message)
                return bool(answer.success)
            time.sleep(0.2)

    def target_speed(self, speed_mps: float) -> bool:
        answer = self.call(
            SetTargetSpeed, "set_target_speed", SetTargetSpeed.Request(speed_mps=speed_mps)
        )
        result = {0: "accepted", 1: "clamped", 2: "refused"}.get(answer.result, "?")
        self.log(
            "set_target_speed",
            speed_mm_s=round(speed_mps * 1e3, 2),
            result=result,
            reason=answer.reason,
            frequency_hz=round(answer.frequency_hz, 2),
            amplitude_percent=round(answer.amplitude_percent, 1),
            predicted_mm_s=round(answer.predicted_speed_mps * 1e3, 2),
        )
        return bool(answer.result != 2)

    def at_target(self) -> bool:
        status = self.speed_status
        return status is not None and status.level == 0 and status.message.startswith("at target")

    def reach_target(self, hold_s: float, timeout_s: float) -> None:
        """Wait until speed/status confirms the target and stays so for ``hold_s`` (at most
        ``timeout_s`` in all); log what the speed monitor said at the end."""
        started = time.monotonic()
        since = math.nan
        while time.monotonic() - started < timeout_s:
            if self.at_target():
                since = time.monotonic() if math.isnan(since) else since
                if time.monotonic() - since >= hold_s:
                    break
            else:
                since = math.nan
            time.sleep(0.1)
        reached = not math.isnan(since)
        self.log(
            "target reached" if reached else "target not confirmed",
            after_s=round((since if reached else time.monotonic()) - started, 1),
        )
        self.watch_speed(0.0)

    def watch_speed(self, seconds: float) -> None:
        """Watch speed/status for a while; log what the speed monitor said at the end."""
        time.sleep(seconds)
        status = self.speed_status
        if status is None:
            self.log("no speed status received")
            return
        self.log(
            "speed status",
            target_mm_s=round(status.target_speed_mps * 1e3, 2),
            estimated_mm_s=(
                round(status.estimated_speed_mps * 1e3, 2)
                if math.isfinite(status.estimated_speed_mps)
                else None
            ),
            estimate_uncertainty_mm_s=(
                round(status.estimated_speed_uncertainty_mps * 1e3, 3)
                if math.isfinite(status.estimated_speed_uncertainty_mps)
                else None
            ),
            transit_mm_s=(
                round(status.transit_speed_mps * 1e3, 2)
                if math.isfinite(status.transit_speed_mps)
                else None
            ),
            feed_rate_ppm=round(status.feed_rate_ppm, 1),
            level=("OK", "WARN", "ERROR")[min(status.level, 2)],
            message=status.message,
        )

    def feed_parts(self, count: int, sensor_index: int, timeout_s: float) -> bool:
        """The feed_parts action: ``count`` parts past sensor ``sensor_index``; True when every
        part came and the feeder stopped."""
        client = self._feed_client
        if not client.wait_for_server(timeout_sec=30.0):
            raise RuntimeError(f"action {self.get_namespace()}/feed_parts is not available")
        goal = FeedParts.Goal(
            mode=FeedParts.Goal.MODE_COUNT, part_count=count, sensor_index=sensor_index
        )
        sent = client.send_goal_async(goal, feedback_callback=self._on_feed_feedback)
        handle = self._await(sent, 30.0, "feed_parts goal")
        if not handle.accepted:
            self.log("feed_parts rejected")
            return False
        result = self._await(handle.get_result_async(), timeout_s, "feed_parts result").result
        self.log(
            "feed_parts",
            outcome=FEED_OUTCOMES[result.outcome] if result.outcome < len(FEED_OUTCOMES) else "?",
            reason=result.reason,
            delivered=result.parts_delivered,
            elapsed_s=round(result.elapsed_s, 2),
            s_per_part=round(result.time_per_part_s, 2)
            if math.isfinite(result.time_per_part_s)
            else None,
            state_after=self.state_name(),
        )
        return bool(result.outcome == FeedParts.Result.OUTCOME_SUCCEEDED)

    def _on_feed_feedback(self, message: Any) -> None:
        feedback = message.feedback
        if feedback.parts_delivered != getattr(self, "_fed", -1):
            self._fed = feedback.parts_delivered
            self.log("feed_parts feedback", delivered=feedback.parts_delivered)

    @staticmethod
    def _await(future: Any, timeout_s: float, what: str) -> Any:
        deadline = time.monotonic() + timeout_s
        while not future.done():
            if time.monotonic() > deadline:
                raise RuntimeError(f"{what}: no answer in {timeout_s} s")
            time.sleep(0.02)
        return future.result()

    def scenario(
        self,
        first_mps: float,
        second_mps: float,
        hold_s: float,
        timeout_s: float,
        feed_count: int = 0,
    ) -> int:
        self.bring_up()
        if not self.wait_for("drive state", lambda: self.drive_state is not None, 30.0):
            return 1
        # driving a feeder whose sensors are not up yet would be driving blind (a cell's nodes
        # start together; the simulator loads its solver first, a real sensor's driver boots)
        if not self.wait_for("the feeder's estimate stream", lambda: self.estimates > 0, 120.0):
            return 1
        self.log("feeder sensors live")
        self.target_speed(first_mps)
        self.start()
        self.reach_target(hold_s, timeout_s)
        self.target_speed(second_mps)
        self.reach_target(hold_s, timeout_s)

        timeout = 2.0
        self.log("heartbeat stopped (simulating a controller crash)")
        self.heartbeat_on = False
        tripped = self.wait_for("watchdog fault", lambda: self.state_name() == "fault", 10.0)
        reason = self.drive_state.fault_reason if self.drive_state else ""
        self.log("watchdog", tripped=tripped, state=self.state_name(), reason=reason)
        time.sleep(timeout)
        self.heartbeat_on = True
        self.log("heartbeat resumed")
        time.sleep(0.5)
        self.trigger("reset_fault")
        self.start()
        self.reach_target(hold_s, timeout_s)
        fed = True
        if feed_count > 0:
            fed = self.feed_parts(feed_count, sensor_index=1, timeout_s=timeout_s)
        self.trigger("stop")
        stopped = self.wait_for("stop", lambda: self.state_name() == "idle", 30.0)
        self.log("stopped", state=self.state_name())
        return 0 if tripped and stopped and fed else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--namespace", default="/demo_cell/feeder_1")
    parser.add_argument("--speed", type=float, default=0.015, help="first target speed [m/s]")
    parser.add_argument("--second-speed", type=float, default=0.008, help="then [m/s]")
    parser.add_argument(
        "--hold", type=float, default=4.0, help="seconds at each speed once it is confirmed"
    )
    parser.add_argument(
        "--timeout", type=float, default=60.0, help="at most this long for each speed [s]"
    )
    parser.add_argument(
        "--feed-parts",
        type=int,
        default=3,
        metavar="N",
        help="then ask for N parts past sensor 1 with the feed_parts action (0: skip)",
    )
    parser.add_argument("--timeline", type=Path, help="write the steps as JSON here")
    args = parser.parse_args(argv)
    with RosSession():
        controller = CellController(args.namespace)
        executor = MultiThreadedExecutor(num_threads=2)
        executor.add_node(controller)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            status = controller.scenario(
                args.speed, args.second_speed, args.hold, args.timeout, args.feed_parts
            )
        except RuntimeError as error:
            controller.log("failed", error=str(error))
            status = 1
        finally:
            if args.timeline is not None:
                args.timeline.write_text(json.dumps(controller.timeline, indent=2) + "\n")
            executor.shutdown()
            spinner.join(timeout=5)
            controller.destroy_node()
    return status


if __name__ == "__main__":
    sys.exit(main())
