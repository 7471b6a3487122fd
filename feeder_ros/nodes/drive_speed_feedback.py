"""Target-speed mode on a real feeder: the calibrated part model and the speed trim (a part of the
drive interface node).

* **Calibrated speed table.** The physics speed table assumes the configured part's friction; the
  estimator calibrates it online and publishes the result (``calibration``,
  ``feeder_ros/PartCalibration``, latched). Each calibration that moves the friction by more than
  0.5 % rebuilds the table in a worker thread (the exact engine takes about a second for the
  demo's grid and releases the GIL; the cache keeps the table) and, once it is built, in
  target-speed mode, chooses the set point for the target again only when the frequency in use
  no longer reaches the target in the new table (else the trimmed set point is kept). A reset
  calibration (state NOMINAL) returns to the configured friction. An identified speed model (a
  file) is measured, not simulated: it is kept.
* **Speed trim.** With ``speed_trim.enabled``, target-speed mode closes the loop on the estimate
  (:class:`~feeder_ros.drive.speed_trim.SpeedTrim`): once the estimate is trustworthy (its
  uncertainty below ``speed_trim.max_uncertainty`` of the target), each estimate of the current
  setting trims the amplitude towards the target, scaled by the physics table's sensitivity of
  speed to amplitude at the set point, through the controller's limits and ramps. When the
  calibration uses sensor transits, each setting is held until a transit of it has been used (at
  most ``speed_trim.transit_wait_s``): a step would void the transits in flight.
  Resonance tracking, when active, trims by itself; the speed trim then stands aside.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from feeder_ros.drive.controller import DriveController
from feeder_ros.drive.speed_model import SpeedModel, TableSpeedModel, steerable
from feeder_ros.drive.speed_trim import SpeedTrim, TrimSettings
from feeder_ros.msg import PartCalibration, VehicleEstimate
from feeder_ros.nodes.ros_time import clock_seconds, stamp_seconds
from feeder_ros.physics.parameters import FeederParameters, ParameterError

__all__ = ["SpeedFeedback", "trim_settings_from"]

LATCHED_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
ESTIMATE_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: a calibration that moves mu_s or mu_d by less than this (relative) keeps the table
REBUILD_TOLERANCE = 0.005


def trim_settings_from(values: dict[str, Any]) -> TrimSettings:
    return TrimSettings(
        gain=values["speed_trim.gain"],
        max_step=values["speed_trim.max_step"],
        max_uncertainty=values["speed_trim.max_uncertainty"],
        transit_wait_s=values["speed_trim.transit_wait_s"],
    )


class SpeedFeedback:
    """See the module docstring. ``apply(controller, now, frequency, amplitude, who)`` sets a
    point through the controller keeping target-speed mode (the node's)."""

    def __init__(
        self,
        node: Node,
        values: dict[str, Any],
        apply: Callable[[DriveController, float, float, float, str], None],
    ) -> None:
        self._node = node
        self._values = values
        self._apply = apply
        self._subscriptions: list[Any] = []
        self._controller: DriveController | None = None
        self._rebuild: Callable[[FeederParameters], SpeedModel] | None = None
        self._plant: FeederParameters | None = None  # the configured plant
        self._table_plant: FeederParameters | None = None  # the one the table was built for
        self._trim = SpeedTrim(trim_settings_from(values))
        self._seen_point: tuple[float, float, bool, float] | None = None
        self._transits_used: int | None = None  # as the last calibration message said
        self.calibration_note = "not configured"
        # the table rebuild runs in a worker thread: what it builds, what it built, what next
        self._build_lock = threading.Lock()
        self._building: FeederParameters | None = None
        self._built: tuple[FeederParameters, SpeedModel | str] | None = None
        self._next: FeederParameters | None = None
        self._generation = 0  # configure/teardown start a new one: older builds are dropped

    def configure(
        self,
        controller: DriveController,
        plant: FeederParameters,
        rebuild: Callable[[FeederParameters], SpeedModel] | None,
    ) -> None:
        """``rebuild(plant)``: the physics table for a plant (None: no table to recalibrate)."""
        self._forget_builds()
        self._controller = controller
        self._plant = self._table_plant = plant
        self._rebuild = rebuild
        self._trim = SpeedTrim(trim_settings_from(self._values))
        self._seen_point = None
        self._transits_used = None
        node = self._node
        topic = self._values["calibration_topic"]
        if rebuild is not None and topic:
            self._subscriptions.append(
                node.create_subscription(PartCalibration, topic, self._on_calibration, LATCHED_QOS)
            )
            self.calibration_note = f"waiting for {node.resolve_topic_name(topic)}"
        else:
            self.calibration_note = "off (no physics table, or no calibration_topic)"
        self._subscriptions.append(
            node.create_subscription(
                VehicleEstimate,
                self._values["speed_trim.estimate_topic"],
                self._on_estimate,
                ESTIMATE_QOS,
            )
        )

    def teardown(self) -> None:
        for subscription in self._subscriptions:
            self._node.destroy_subscription(subscription)
        self._subscriptions = []
        self._controller = None
        self._forget_builds()

    def _forget_builds(self) -> None:
        with self._build_lock:  # a build still running is dropped when it ends
            self._generation += 1
            self._building = self._next = None
            self._built = None

    def settings_changed(self) -> None:
        self._trim.settings = trim_settings_from(self._values)

    @property
    def trim_note(self) -> str:
        return self._trim.last_note if self._values["speed_trim.enabled"] else "off"

    # -- the loop --------------------------------------------------------------------------------
    def tick(self, controller: DriveController, now: float, tracking_active: bool) -> None:
        """Install a rebuilt table; tell the trim when a new setting is reached (or that
        trimming stops)."""
        self._take_built_table(controller, now)
        seen = self._setting(controller)
        if not (controller.running and controller.speed_mode) or tracking_active:
            self._trim.stop()
            self._seen_point = None
            return
        if seen != self._seen_point:
            self._seen_point = seen
            self._trim.setting_changed(now + controller.ramp.remaining_s(now))

    @staticmethod
    def _setting(controller: DriveController) -> tuple[float, float, bool, float]:
        point = controller.set_point
        return (
            point.frequency_hz,
            point.amplitude_percent,
            controller.running,
            controller.target_speed_mps,
        )

    def _on_estimate(self, message: VehicleEstimate) -> None:
        controller = self._controller
        if controller is None or not self._values["speed_trim.enabled"]:
            return
        if not (controller.running and controller.speed_mode) or self._seen_point is None:
            return
        if self._setting(controller) != self._seen_point:
            # a new target or set point the trim has not been told of yet (the next tick does):
            # this estimate is of the previous setting, and judged against the new target it
            # asked for a -15 % step when the demo's target went from 15 to 8 mm/s
            return
        stamp = message.header.stamp
        point = controller.set_point
        model = controller.speed_model
        sensitivity = (
            model.amplitude_sensitivity(point.frequency_hz, point.amplitude_percent)
            if isinstance(model, TableSpeedModel)
            else math.nan  # an identified model: unknown, the trim takes 1
        )
        amplitude = self._trim.reading(
            stamp_seconds(stamp),
            message.window_s,
            message.mean_speed_mps,
            message.mean_speed_uncertainty_mps,
            controller.target_speed_mps,
            point.amplitude_percent,
            sensitivity,
        )
        if amplitude is None:
            return
        now = clock_seconds(self._node.get_clock())
        self._apply(controller, now, controller.set_point.frequency_hz, amplitude, "speed trim")
        self._node.get_logger().info(
            f"speed trim: {self._trim.last_note}: {amplitude:.2f} % for "
            f"{1e3 * controller.target_speed_mps:g} mm/s (estimate "
            f"{1e3 * message.mean_speed_mps:.2f} +- {1e3 * message.mean_speed_uncertainty_mps:.2f})"
        )

    # -- calibration -------------------------------------------------------------------------
    def _on_calibration(self, message: PartCalibration) -> None:
        stamp = message.header.stamp
        used = int(message.transits_used)
        # the first message is the baseline (a calibration restored from its file counts the
        # transits of earlier runs); a transit is used when the count rises (fewer: a reset)
        if self._transits_used is not None and used > self._transits_used:
            self._trim.transit_used(stamp_seconds(stamp))
        self._transits_used = used
        controller, plant, rebuild = self._controller, self._plant, self._rebuild
        if controller is None or plant is None or rebuild is None:
            return
        if message.state == PartCalibration.STATE_NOMINAL:
            wanted = plant
        else:
            g_kappa = plant.gravity_mps2 * plant.friction_multiplier
            mu_s = message.stick_limit_mps2 / g_kappa
            mu_d = message.slip_deceleration_mps2 / g_kappa
            try:
                wanted = plant.with_changes(static_friction=mu_s, kinetic_friction=mu_d)
            except (ParameterError, ValueError) as error:
                self._node.get_logger().warning(f"calibration not used: {error}")
                return
        with self._build_lock:
            current = self._building or self._table_plant
            assert current is not None
            if all(
                math.isclose(
                    getattr(wanted, name), getattr(current, name), rel_tol=REBUILD_TOLERANCE
                )
                for name in ("static_friction", "kinetic_friction")
            ):
                return
            if self._building is not None:
                self._next = wanted  # built when the running build ends (the latest wins)
                return
            self._start_build(wanted, rebuild)

    def _start_build(
        self, wanted: FeederParameters, rebuild: Callable[[FeederParameters], SpeedModel]
    ) -> None:
        """Build the table for ``wanted`` in a worker thread (the build takes about a second;
        the executor's callbacks, and in a composed cell the other nodes', keep running: the
        solver releases the GIL). Called with the build lock held."""
        self._building = wanted
        generation = self._generation

        def work() -> None:
            try:
                result: SpeedModel | str = rebuild(wanted)
            except (ValueError, RuntimeError, OSError) as error:
                result = str(error)
            with self._build_lock:
                if generation == self._generation:
                    self._built = (wanted, result)

        threading.Thread(target=work, name="speed-table-rebuild", daemon=True).start()

    def _take_built_table(self, controller: DriveController, now: float) -> None:
        """Install a table the worker finished (executor thread: the controller is not shared)."""
        with self._build_lock:
            if self._built is None:
                return
            wanted, result = self._built
            self._built, self._building = None, None
            following, self._next = self._next, None
            if following is not None and self._rebuild is not None:
                self._start_build(following, self._rebuild)
        if isinstance(result, str):
            self._node.get_logger().error(f"speed table for the calibrated part failed: {result}")
            return
        self._install(controller, now, wanted, result)

    def _install(
        self, controller: DriveController, now: float, wanted: FeederParameters, model: SpeedModel
    ) -> None:
        self._table_plant = wanted
        controller.speed_model = model
        self.calibration_note = (
            f"table for mu_s {wanted.static_friction:.4g}, mu_d {wanted.kinetic_friction:.4g}"
        )
        self._node.get_logger().info(f"speed model recalibrated: {self.calibration_note}")
        if controller.speed_mode and math.isfinite(controller.target_speed_mps):
            trimmed = controller.set_point
            if isinstance(model, TableSpeedModel):
                here = model.choose(controller.target_speed_mps, trimmed.frequency_hz)
                keep = here is not None and steerable(
                    model.amplitude_sensitivity(here.frequency_hz, here.amplitude_percent)
                )
            else:
                choice = model.choose(controller.target_speed_mps)
                keep = choice is not None and math.isclose(
                    choice.frequency_hz, trimmed.frequency_hz
                )
            if keep:
                # the frequency in use still reaches the target where the amplitude steers the
                # speed: the trim's amplitude holds it on the real feeder. A new choice would
                # throw that work away, and a frequency hop on every small recalibration (seen
                # in the demo: 30 -> 22 -> 30 Hz within 20 s) is a new operating point each
                # time, its transits voided.
                return
            answer = controller.set_target_speed(
                now, controller.target_speed_mps, controller.set_ramp_time_s
            )
            self._node.get_logger().info(
                f"target {1e3 * controller.target_speed_mps:g} mm/s on the recalibrated model: "
                f"{answer.frequency_hz:.3f} Hz, {answer.amplitude_percent:.2f} % "
                f"({answer.outcome.name.lower()}{': ' + answer.reason if answer.reason else ''})"
            )
