"""``drive_interface``: the managed node a pick-and-place cell controller talks to.

Lifecycle: configure reads the limits, builds the speed model and connects the backend; activate
permits output; deactivate ramps to zero (output off when there); cleanup and shutdown disconnect.
Services answer accepted / clamped / refused with a reason. All decisions are made by
:class:`feeder_ros.drive.controller.DriveController` (ROS-free, unit-tested); this module turns
parameters, messages, service calls and lifecycle transitions into calls on it, on the node clock.

Backends: ``sim`` publishes ``drive/command`` (freshly stamped, ``publish_rate_hz``, enabled=false
when off) for the platform simulator; ``modbus_tcp`` talks to a real feeder controller
(register map in ``config/drive_interface.yaml``).

Resonance tracking (``tracking.enabled``): in target-speed mode, while running, a
:class:`feeder_ros.drive.resonance_tracker.ResonanceTracker` starts from the speed model's set point
and moves the frequency onto the measured part-speed peak (square frequency dither, extremum
seeking) while trimming the amplitude to hold the target speed, from the part speed on
``tracking.feedback_topic`` (the estimator's ``estimate`` or the speed monitor's ``speed/status``).
When it runs and how its set points reach the controller is
:class:`feeder_ros.drive.tracked_control.TrackedControl` (ROS-free), the readings' subscription
:mod:`feeder_ros.nodes.drive_tracking_feedback`. Stale feedback holds the
tracked centre frequency and amplitude and is reported in ``/diagnostics`` (WARN) and
``drive/state`` (``status`` = TRACKING_HOLD). The diagnostics' level and summary are
:func:`feeder_ros.drive.health.drive_health`.

Part feeding (level control, ``feed_parts``) is :mod:`feeder_ros.nodes.drive_feeding`,
vibration-amplitude regulation (``amplitude.*``, ``set_vibration_amplitude``)
:mod:`feeder_ros.nodes.drive_amplitude`, both ticked before the controller. The services'
callbacks are the mixin :class:`feeder_ros.nodes.drive_services.DriveServices`.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import InvalidTopicNameException
from rclpy.expand_topic_name import expand_topic_name
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.validate_full_topic_name import validate_full_topic_name
from std_msgs.msg import Header

from feeder_ros.drive.backend import BackendStatus, DriveBackend, DriveOutput
from feeder_ros.drive.controller import DriveController, DriveState
from feeder_ros.drive.health import Level, drive_health, drive_values
from feeder_ros.drive.level_control import LevelControl
from feeder_ros.drive.limits import DriveLimits, Outcome
from feeder_ros.drive.modbus import ModbusTcpBackend
from feeder_ros.drive.resonance_tracker import TrackerMode
from feeder_ros.drive.speed_model import SpeedModel
from feeder_ros.drive.speed_model_source import (
    SpeedModelSource,
    build_speed_model,
    physics_speed_table,
)
from feeder_ros.drive.tracked_control import TrackedControl, apply_loop_point
from feeder_ros.msg import DriveState as DriveStateMsg
from feeder_ros.nodes.diagnostics import diagnostic_array, diagnostic_status
from feeder_ros.nodes.drive_amplitude import AmplitudeShell
from feeder_ros.nodes.drive_feeding import Feeding
from feeder_ros.nodes.drive_interface_parameters import (
    AT_CONFIGURE,
    DEFAULTS,
    INTERFACE,
    LIMIT_PARAMETERS,
    PARAMETERS,
    TRACKER_FIELDS,
    level_settings_from,
    limits_from,
    modbus_settings_from,
    plant_from,
    register_map_from,
    speed_model_source_from,
    tracker_settings_from,
)
from feeder_ros.nodes.drive_services import DriveServices
from feeder_ros.nodes.drive_sim_link import SimLink
from feeder_ros.nodes.drive_speed_feedback import SpeedFeedback
from feeder_ros.nodes.drive_tracking_feedback import TrackingFeedback
from feeder_ros.nodes.ros_parameters import declare_parameters, validator
from feeder_ros.nodes.ros_time import clock_seconds
from feeder_ros.nodes.runner import run_node
from feeder_ros.physics.parameters import FeederParameters

if TYPE_CHECKING:
    from feeder_ros.ros_compat import AnyParameter

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: threads a speed table not yet cached is simulated on at configure: one core is left to the
#: nodes of the cell (the simulator and estimator must keep their sample rate meanwhile)
SPEED_TABLE_THREADS = max(1, (os.cpu_count() or 1) - 1)


def check_topic_name(name: str, parameter: str) -> None:
    """Raise ValueError naming ``parameter`` unless ``name`` is a valid ROS topic name."""
    try:
        validate_full_topic_name(expand_topic_name(name, INTERFACE.node_name, "/"))
    except (ValueError, InvalidTopicNameException) as error:
        raise ValueError(f"{parameter}={name!r} is not a topic name: {error}") from None


def check_combination(values: dict[str, Any]) -> None:
    """Every combination the node could be configured with; raises with the offending values."""
    limits = limits_from(values)
    tracker_settings_from(values).check_against(limits)
    check_topic_name(values["tracking.feedback_topic"], "tracking.feedback_topic")
    check_topic_name(values["amplitude.imu_topic"], "amplitude.imu_topic")
    register_map_from(values)
    plant_from(values)
    level_settings_from(values)
    if values["modbus.reconnect_min_s"] > values["modbus.reconnect_max_s"]:
        raise ValueError(
            f"modbus.reconnect_min_s={values['modbus.reconnect_min_s']:g} exceeds "
            f"modbus.reconnect_max_s={values['modbus.reconnect_max_s']:g}"
        )


class DriveInterface(DriveServices, LifecycleNode):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(INTERFACE.node_name, **kwargs)
        self._values = declare_parameters(self, PARAMETERS.values(), DEFAULTS)
        check_combination(self._values)
        self.add_on_set_parameters_callback(
            validator(PARAMETERS, check_all=check_combination, current=lambda: self._values)
        )
        self.add_on_set_parameters_callback(self._refuse_configure_time_changes)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._controller: DriveController | None = None
        self._backend: DriveBackend | None = None
        # the backend's status as the last control tick saw it: diagnostics report that one, so
        # they never name a fault the controller has not latched yet (and the state says so)
        self._backend_status: BackendStatus | None = None
        self._logged_fault = ""  # the latched fault reason last logged (each new one is logged)
        self._speed_source = "none"
        self._loop_timers: list[Any] = []
        self._tracked: TrackedControl | None = None
        self._tracking_feedback: TrackingFeedback | None = None
        self._sim_link: SimLink | None = None  # sim backend: drive/command and parts/state
        self._speed_feedback = SpeedFeedback(self, self._values, self._apply_point)
        self._last_output = DriveOutput(False, 0.0, 0.0, 0.0)
        # plain publishers: they exist unconfigured, and keep publishing the ramp to zero after
        # deactivate (lifecycle publishers would fall silent at once)
        self._state_pub = self.create_publisher(DriveStateMsg, "drive/state", RELIABLE)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        self.create_subscription(Header, "heartbeat", self._on_heartbeat, RELIABLE)
        self._create_services()
        self._feeding = Feeding(self, self._values)
        self._amplitude = AmplitudeShell(self, self._values)
        # diagnostics in every lifecycle state: an unconfigured drive is worth a WARN too
        self.create_timer(self._values["diagnostics_period_s"], self._publish_diagnostics)

    # -- time and parameters -------------------------------------------------------------------
    def _now(self) -> float:
        return clock_seconds(self.get_clock())

    def _refuse_configure_time_changes(self, parameters: list[AnyParameter]) -> SetParametersResult:
        """A parameter read at configure changes only while the node is unconfigured: changed
        later, it would not act until the next configure, while drive/state and the diagnostics
        already reported it (a backend, a feedback topic that is not the one in use)."""
        if self._controller is None:
            return SetParametersResult(successful=True)
        for parameter in parameters:
            if parameter.name in AT_CONFIGURE and parameter.value != self._values[parameter.name]:
                return SetParametersResult(
                    successful=False,
                    reason=f"{parameter.name} is read at configure: deactivate and clean up the "
                    "node (unconfigured), set it, then configure again",
                )
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[AnyParameter]) -> None:
        changed = {p.name for p in parameters if p.name in PARAMETERS}
        for parameter in parameters:
            if parameter.name in PARAMETERS:
                self._values[parameter.name] = parameter.value
        controller = self._controller
        if controller is None:
            return
        if changed & {spec.name for spec in LIMIT_PARAMETERS} - {"heartbeat_timeout_s"}:
            note = controller.update_limits(limits_from(self._values), self._now())
            if note:
                self.get_logger().warning(f"new limits moved the set point: {note}")
        if "heartbeat_timeout_s" in changed:
            controller.watchdog.timeout_s = float(self._values["heartbeat_timeout_s"])
        if "unreachable_speed" in changed:
            controller.clamp_unreachable_speed = self._values["unreachable_speed"] == "clamp"
        if any(name.startswith("speed_trim.") for name in changed):
            self._speed_feedback.settings_changed()
        tracked = self._tracked
        if tracked is None:
            return
        now = self._now()
        tracked.enabled = bool(self._values["tracking.enabled"])
        limits_changed = bool(changed & {spec.name for spec in LIMIT_PARAMETERS})
        settings_changed = bool(changed & {f"tracking.{name}" for name in TRACKER_FIELDS})
        if settings_changed or limits_changed:
            tracked.settings_changed(
                controller,
                now,
                tracker_settings_from(self._values) if settings_changed else None,
                limits_from(self._values) if limits_changed else None,
            )
        if "tracking.enabled" in changed and not tracked.enabled:
            tracked.stop(controller, now, "tracking.enabled is false", hold=True)

    # -- lifecycle -----------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        values = dict(self._values)
        try:
            limits = limits_from(values)
            level = LevelControl(level_settings_from(values))
            source = speed_model_source_from(values, SPEED_TABLE_THREADS)
            speed_model, self._speed_source = build_speed_model(
                source, plant_from(values), limits, self._speed_table_not_cached
            )
        except (ValueError, RuntimeError, OSError) as error:
            self.get_logger().error(f"configure failed: {error}")
            return TransitionCallbackReturn.FAILURE
        self._controller = DriveController(
            limits,
            heartbeat_timeout_s=values["heartbeat_timeout_s"],
            speed_model=speed_model,
            clamp_unreachable_speed=values["unreachable_speed"] == "clamp",
        )
        self._feeding.configure(self._controller, level)
        self._amplitude.configure(self._controller)
        if values["backend"] == "sim":
            self._sim_link = SimLink(
                self, 1.0 / values["publish_rate_hz"], values["sim_feedback_timeout_s"]
            )
            self._backend = self._sim_link.backend
        else:
            self._backend = ModbusTcpBackend(
                modbus_settings_from(values), register_map_from(values)
            )
        self._backend_status = None
        self._backend.connect()
        table = source.enabled and not source.file
        self._speed_feedback.configure(
            self._controller,
            plant_from(values),
            (lambda plant: self._speed_table(plant, limits, source)) if table else None,
        )
        self._tracked = TrackedControl(tracker_settings_from(values), limits, self._log)
        self._tracked.enabled = bool(values["tracking.enabled"])
        self._tracking_feedback = TrackingFeedback(
            self, self._tracked, self._values, self._feeding.set_speed
        )
        self._period_s = 1.0 / values["publish_rate_hz"]
        self._loop_timers = [self.create_timer(self._period_s, self._tick)]
        self.get_logger().info(
            f"configured: backend {values['backend']}, {limits.min_frequency_hz:g}-"
            f"{limits.max_frequency_hz:g} Hz, 0-{limits.max_amplitude_percent:g} %, "
            f"speed model: {self._speed_source}; resonance tracking "
            f"{'on' if values['tracking.enabled'] else 'off'}, feedback "
            f"{self.resolve_topic_name(values['tracking.feedback_topic'])} "
            f"({values['tracking.feedback_type']})"
        )
        return TransitionCallbackReturn.SUCCESS

    def _speed_table_not_cached(self, error: OSError) -> None:
        self.get_logger().warning(
            f"speed table computed but not cached ({error}); it is used all the same, and "
            "computed again at the next configure"
        )

    def _speed_table(
        self, plant: FeederParameters, limits: DriveLimits, source: SpeedModelSource
    ) -> SpeedModel:
        """The physics table for a calibrated ``plant``, named in diagnostics."""
        model, self._speed_source = physics_speed_table(
            plant, limits, source, self._speed_table_not_cached
        )
        return model

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self._controller is not None
        self._controller.activate(self._now())
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self._controller is not None
        ramp_s = self._controller.deactivate(self._now())
        self.get_logger().info(f"deactivated: ramping to zero in {ramp_s:.3f} s, then output off")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def _teardown(self) -> None:
        """Output off at once, backend disconnected, timers and drive/command gone."""
        for timer in self._loop_timers:
            self.destroy_timer(timer)
        self._loop_timers = []
        self._tracked = None
        self._speed_feedback.teardown()
        self._feeding.teardown(self._now())
        self._amplitude.teardown()
        if self._tracking_feedback is not None:
            self._tracking_feedback.close()
            self._tracking_feedback = None
        if self._controller is not None:
            self._controller.emergency_stop(self._now(), "shutting down")
            self._controller = None
        if self._backend is not None:
            self._backend.disconnect()
            self._backend = None
        if self._sim_link is not None:
            self._sim_link.close()
            self._sim_link = None

    def destroy_node(self) -> None:
        try:
            self._teardown()
        except Exception as error:  # the context may already be shut down: log, go on
            self.get_logger().warning(f"teardown on exit: {error}")
        # a constructor that refused its parameters never made it (Kilted's context still
        # destroys such a node at shutdown)
        for shell in (getattr(self, "_feeding", None), getattr(self, "_amplitude", None)):
            if shell is not None:
                shell.destroy()
        super().destroy_node()  # type: ignore[no-untyped-call,unused-ignore]  # untyped on Jazzy

    # -- the loop ------------------------------------------------------------------------------
    def _tick(self) -> None:
        controller, backend = self._controller, self._backend
        if controller is None or backend is None:
            return
        now = self._now()
        if self._sim_link is not None:
            self._sim_link.tick()
        status = self._backend_status = backend.status()
        if status.fault != controller.backend_fault:
            was_faulted = bool(controller.backend_fault)
            controller.set_backend_fault(now, status.fault)
            if status.fault and not was_faulted:
                self.get_logger().error(f"backend fault: {status.fault}")
            elif status.fault:  # the same fault, new details (e.g. the next retry delay)
                self.get_logger().debug(f"backend fault: {status.fault}")
            else:
                self.get_logger().info("backend fault cleared (reset_fault to resume)")
        tracked = self._tracked
        if tracked is not None:
            tracked.tick(controller, now)
        self._speed_feedback.tick(controller, now, tracked is not None and tracked.active)
        self._feeding.tick(controller, now, self._last_output)
        self._amplitude.tick(controller, now, self._last_output)
        output = controller.tick(now, self._period_s)
        if controller.fault_reason != self._logged_fault:
            # every fault latched here (the heartbeat watchdog, ...) is logged once; a backend
            # fault and an e-stop are logged where they arrive
            if (
                controller.fault_reason
                and controller.state == DriveState.FAULT
                and not controller.fault_reason.startswith("backend: ")
            ):
                self.get_logger().error(
                    f"output off, fault latched: {controller.fault_reason} "
                    "(reset_fault, then start, to resume)"
                )
            self._logged_fault = controller.fault_reason
        backend.write(output)
        self._last_output = output
        self._publish_state(controller, output)

    def _publish_state(self, controller: DriveController, output: DriveOutput) -> None:
        message = DriveStateMsg()
        message.header.stamp = self.get_clock().now().to_msg()
        message.state = int(controller.state)
        message.frequency_hz = output.frequency_hz
        message.amplitude_percent = output.amplitude_percent
        message.amplitude_n = output.amplitude_n
        message.target_frequency_hz = controller.set_point.frequency_hz
        message.target_amplitude_percent = controller.set_point.amplitude_percent
        message.speed_mode = controller.speed_mode
        message.target_speed_mps = controller.target_speed_mps if controller.speed_mode else 0.0
        message.backend = self._values["backend"]
        message.fault_reason = controller.fault_reason
        self._feeding.fill_state(message, controller)
        self._amplitude.fill_state(message, controller)
        if self._tracked is not None:
            tracking = self._tracked.status(self._now())
            message.status = int(tracking.mode)
            message.tracked_frequency_hz = tracking.centre_frequency_hz
            message.tracked_amplitude_percent = tracking.amplitude_percent
            message.measured_speed_mps = tracking.measured_speed_mps
        else:
            message.status = int(TrackerMode.OFF)
            message.tracked_frequency_hz = math.nan
            message.tracked_amplitude_percent = math.nan
            message.measured_speed_mps = math.nan
        self._state_pub.publish(message)

    # -- resonance tracking --------------------------------------------------------------------
    def _log(self, severity: str, text: str) -> None:
        """The ROS-free cores' log lines ("repeating": a warning that may come every tick)."""
        logger = self.get_logger()
        if severity == "info":
            logger.info(text)
        elif severity == "repeating":
            logger.warning(text, throttle_duration_sec=5.0)
        else:
            logger.warning(text)

    def _apply_point(
        self,
        controller: DriveController,
        now: float,
        frequency_hz: float,
        amplitude_percent: float,
        who: str,
    ) -> None:
        answer = apply_loop_point(controller, now, frequency_hz, amplitude_percent)
        if answer.outcome is Outcome.REFUSED:
            self._log("repeating", f"{who} set point refused: {answer.reason}")

    def _publish_diagnostics(self) -> None:
        controller, backend = self._controller, self._backend
        if controller is None or backend is None:
            self._publish_status(
                Level.WARN,
                "unconfigured: output off",
                "none",
                {"lifecycle": "unconfigured or finalized"},
            )
            return
        status = self._backend_status if self._backend_status is not None else backend.status()
        now = self._now()
        tracked = self._tracked
        health = drive_health(
            controller,
            status,
            now,
            self._amplitude.warning(),
            tracked.status(now) if tracked is not None else None,
        )
        values = {
            **drive_values(controller, status, self._last_output, now),
            "speed model": self._speed_source,
            "speed model calibration": self._speed_feedback.calibration_note,
            "speed trim": self._speed_feedback.trim_note,
            **self._feeding.diagnostics(),
            **self._amplitude.diagnostics(),
        }
        if self._sim_link is not None:  # silence after its own stall counts later
            values.update(self._sim_link.stalls.diagnostic_values())
        if tracked is not None:
            feedback = (
                f"{self.resolve_topic_name(self._values['tracking.feedback_topic'])} "
                f"({self._values['tracking.feedback_type']})"
            )
            values.update(tracked.values(now, feedback))
        self._publish_status(health.level, health.summary, backend.name, values)

    def _publish_status(
        self, level: int, summary: str, hardware_id: str, values: dict[str, str]
    ) -> None:
        name = f"{self.get_fully_qualified_name()}: drive"
        status = diagnostic_status(name, level, summary, hardware_id, values)
        self._diagnostics_pub.publish(diagnostic_array(self.get_clock().now().to_msg(), status))

    # -- inputs --------------------------------------------------------------------------------
    def _on_heartbeat(self, message: Header) -> None:
        if self._controller is not None:
            self._controller.heartbeat(self._now())


NODE_CLASS = DriveInterface


def main(args: list[str] | None = None) -> int:
    return run_node(DriveInterface, args)


if __name__ == "__main__":
    raise SystemExit(main())
