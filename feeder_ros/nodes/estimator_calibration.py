"""The vehicle estimator's online calibration on the ROS graph (a part of the estimator node).

Sensor transits (``parts/sensor_events``) and an operator's measured speed
(``calibration/measured_speed``) go through the ROS-free
:class:`~feeder_ros.estimation.online_calibration.MeasurementSource` into the
:class:`~feeder_ros.estimation.calibration.Calibrator`; every accepted update gives the estimator
the new part belief, is published (latched) on ``calibration`` and written to
``calibration.file`` (atomically). Transits are folded in by a worker thread, in their order: an
update takes 30 ms to a few hundred (more on a loaded machine), and the node's lock stays free for
the estimates meanwhile. ``calibration/reset`` returns to the nominal part. A calibration
file that cannot be used at start (corrupt, foreign, another version) is reported (ERROR log,
WARN in ``/diagnostics``) and the node runs on the nominal part.
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from feeder_ros.estimation.calibration import CalibrationResult, Calibrator, SpeedMeasurement
from feeder_ros.estimation.calibration_file import (
    CalibrationFileError,
    read_calibration,
    write_calibration,
)
from feeder_ros.estimation.part_belief import PartBelief
from feeder_ros.estimation.stick_slip_observer import PartModel
from feeder_ros.estimation.vehicle_estimator import VehicleEstimator
from feeder_ros.msg import PartCalibration, PartSensorEvent
from feeder_ros.nodes.diagnostics import diagnostic_status
from feeder_ros.nodes.ros_time import stamp_seconds
from feeder_ros.nodes.vehicle_estimator_parameters import measurement_source
from feeder_ros.srv import SetMeasuredSpeed

__all__ = ["EstimatorCalibration"]

LATCHED_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
EVENT_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


class EstimatorCalibration:
    """See the module docstring. ``lock`` guards ``estimator()`` (the node's lock)."""

    def __init__(
        self,
        node: Node,
        lock: threading.Lock,
        estimator: Callable[[], VehicleEstimator],
        nominal: PartModel,
        values: dict[str, Any],
    ) -> None:
        self._node = node
        self._lock = lock
        self._estimator = estimator
        self._values = values
        self._enabled = bool(values["calibration.enabled"])
        self._source = measurement_source(values)
        self._file = values["calibration.file"]
        self._file_problem = ""
        self._refused = 0
        self._message = "nominal part (no measurement yet)"
        # the calibrator is the worker's while it folds a measurement in: this lock guards it; the
        # node's lock (always taken first) only to hand the estimator a belief
        self._cal_lock = threading.Lock()
        self._count_lock = threading.Lock()  # the refusal count and message (any thread)
        self._calibrator = self._start(nominal)
        self._queue: queue.SimpleQueue[tuple[int, SpeedMeasurement] | None] = queue.SimpleQueue()
        # closed before the node is destroyed: the worker then publishes nothing more (a publish
        # on a destroyed node raises) and ends at its next queue item
        self._publish_lock = threading.Lock()
        self._closed = False
        self._generation = 0  # a reset or a new nominal part drops the queued measurements
        self._publisher = node.create_publisher(PartCalibration, "calibration", LATCHED_QOS)
        self.worker: threading.Thread | None = None
        if self._enabled:
            self.worker = threading.Thread(target=self._work, name="part-calibration", daemon=True)
            self.worker.start()
            node.create_subscription(
                PartSensorEvent, "parts/sensor_events", self._on_sensor_event, EVENT_QOS
            )
            node.create_service(
                SetMeasuredSpeed, "calibration/measured_speed", self._on_measured_speed
            )
            node.create_service(Trigger, "calibration/reset", self._on_reset)
        self._publish()

    def _start(self, nominal: PartModel) -> Calibrator:
        prior = PartBelief.prior(
            nominal,
            self._values["calibration.friction_uncertainty"],
            self._values["calibration.gain_uncertainty"],
        )
        calibrator = Calibrator(prior)
        if self._enabled and self._file:
            try:
                stored = read_calibration(self._file, nominal)
            except CalibrationFileError as error:
                self._file_problem = f"{error}: running on the nominal part"
                self._node.get_logger().error(self._file_problem)
            else:
                if stored is not None:
                    calibrator.restore(stored)
                    self._message = f"read from {self._file}"
        return calibrator

    @property
    def belief(self) -> PartBelief:
        return self._calibrator.belief

    def renominate(self, nominal: PartModel) -> None:
        """The nominal part changed (a parameter): the calibration of the old one is void."""
        with self._cal_lock:
            self._generation += 1
            self._calibrator = Calibrator(
                PartBelief.prior(
                    nominal,
                    self._values["calibration.friction_uncertainty"],
                    self._values["calibration.gain_uncertainty"],
                )
            )
            self._message = "nominal part changed: calibration restarted"
            self._publish()

    # -- inputs ----------------------------------------------------------------------------------
    def _on_sensor_event(self, message: PartSensorEvent) -> None:
        part = None if message.part_id == PartSensorEvent.PART_ID_UNKNOWN else message.part_id
        stamp = stamp_seconds(message.header.stamp)
        with self._lock:
            estimator = self._estimator()
            outcome = self._source.on_sensor_edge(
                estimator, stamp, message.sensor_index, message.sensor_position_m, part,
                message.present,
            )  # fmt: skip
        self._handle(outcome)

    def stream_advanced(self) -> None:
        """The estimator has taken in more samples: the transits that waited for them."""
        if not self._enabled or not self._source.waiting:
            return  # (called on every publish: no lock unless a transit waits)
        with self._lock:
            outcomes = self._source.due(self._estimator())
        for outcome in outcomes:
            self._handle(outcome)

    def _handle(self, outcome: SpeedMeasurement | str | None) -> None:
        if isinstance(outcome, SpeedMeasurement):
            # folded in by the worker, off the executor's thread
            self._queue.put((self._generation, outcome))
        elif outcome:
            self._refuse(outcome)  # (without the calibration lock: an update may be running)

    def _on_measured_speed(
        self, request: SetMeasuredSpeed.Request, response: SetMeasuredSpeed.Response
    ) -> SetMeasuredSpeed.Response:
        with self._lock:
            outcome = self._source.operator_speed(
                self._estimator(), request.speed_mps, request.uncertainty_mps
            )
        if not isinstance(outcome, SpeedMeasurement):
            self._refuse(str(outcome))
            response.accepted, response.reason = False, str(outcome)
        else:
            result = self._fold_in(self._generation, outcome)
            response.accepted, response.reason = result.accepted, result.reason
            response.predicted_speed_mps = result.predicted_mps
            response.predicted_uncertainty_mps = result.predicted_uncertainty_mps
        belief = self._calibrator.belief
        response.static_friction = belief.static_friction
        response.kinetic_friction = belief.kinetic_friction
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._lock, self._cal_lock:  # (the locks' order everywhere: the node's first)
            self._generation += 1  # measurements still queued were for the old calibration
            self._calibrator.restore(
                PartBelief.prior(
                    self._calibrator.belief.nominal,
                    self._values["calibration.friction_uncertainty"],
                    self._values["calibration.gain_uncertainty"],
                )
            )
            with self._count_lock:
                self._refused = 0
                self._message = "reset to the nominal part"
            self._estimator().set_belief(self._calibrator.belief)
            self._persist()
        self._publish()
        response.success, response.message = True, self._message
        return response

    # -- updates -----------------------------------------------------------------------------
    def _work(self) -> None:
        """The worker: folds the queued transits in, one at a time, in their order."""
        while (item := self._queue.get()) is not None:
            generation, measurement = item
            try:
                self._fold_in(generation, measurement)
            except Exception as error:  # the worker must outlive one bad update
                self._refuse(f"calibration update failed: {error!r}")

    def close(self) -> None:
        """Stop publishing and end the worker (before the node is destroyed); an update being
        folded in meanwhile still reaches the file, not the topic."""
        with self._publish_lock:
            self._closed = True
        self._queue.put(None)

    def _fold_in(self, generation: int, measurement: SpeedMeasurement) -> CalibrationResult:
        """Fold ``measurement`` in (with the calibration lock: the estimates go on meanwhile),
        then hand the estimator the new belief (with the node's lock, then the calibration's, as
        everywhere), unless a reset or a new nominal part came in between."""
        with self._cal_lock:
            if generation != self._generation:
                return CalibrationResult(False, "calibration restarted", self._calibrator.belief)
            result = self._calibrator.add(measurement)
        if not result.accepted:
            self._refuse(result.reason)
            return result
        with self._lock, self._cal_lock:
            if generation != self._generation:
                return result
            with self._count_lock:
                self._message = result.reason
            self._estimator().set_belief(result.belief)
            self._persist()
        self._publish()
        return result

    def _refuse(self, reason: str) -> None:
        with self._count_lock:
            self._refused += 1
            self._message = f"refused: {reason}"
        self._node.get_logger().warning(self._message, throttle_duration_sec=5.0)
        self._publish()

    def _persist(self) -> None:
        if not self._file:
            return
        try:
            write_calibration(self._file, self._calibrator.belief)
        except OSError as error:
            self._file_problem = f"cannot write {self._file}: {error}"
            self._node.get_logger().error(self._file_problem, throttle_duration_sec=30.0)
        else:
            self._file_problem = ""

    def _publish(self) -> None:
        with self._publish_lock:
            if not self._closed:
                self._publisher.publish(self.message())

    # -- outputs -----------------------------------------------------------------------------
    def message(self) -> PartCalibration:
        belief = self._calibrator.belief
        std = belief.std
        cov = belief.covariance
        corr = cov[0, 1] / (std[0] * std[1]) if std[0] > 0.0 and std[1] > 0.0 else 0.0
        msg = PartCalibration()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        points = len(belief.points)
        used = belief.transits + belief.operator_speeds
        msg.state = (
            PartCalibration.STATE_NOMINAL
            if used == 0
            else PartCalibration.STATE_CALIBRATED
            if points >= 2
            else PartCalibration.STATE_CALIBRATING
        )
        msg.stick_limit_mps2 = belief.stick_limit_mps2
        msg.stick_limit_uncertainty = float(std[0])
        msg.slip_deceleration_mps2 = belief.slip_deceleration_mps2
        msg.slip_deceleration_uncertainty = float(std[1])
        msg.stick_slip_correlation = float(corr) if math.isfinite(corr) else 0.0
        msg.static_friction = belief.static_friction
        msg.kinetic_friction = belief.kinetic_friction
        msg.accelerometer_gain = belief.gain
        msg.accelerometer_gain_uncertainty = float(std[2])
        msg.transits_used = belief.transits
        msg.operator_speeds_used = belief.operator_speeds
        msg.operating_points = points
        msg.measurements_refused = self._refused
        msg.message = self._message
        return msg

    def diagnostic_status(self, name: str) -> DiagnosticStatus:
        """The calibration's state for ``/diagnostics``: WARN for a calibration file that could not
        be used or written and for a refused measurement (until the next accepted one)."""
        belief = self._calibrator.belief
        std = belief.std
        level, text = 0, self._message
        if not self._enabled:
            text = "disabled: nominal part"
        elif self._file_problem:
            level, text = 1, self._file_problem
        elif self._message.startswith("refused:"):
            level = 1
        values = {
            "static_friction": f"{belief.static_friction:.4g}",
            "kinetic_friction": f"{belief.kinetic_friction:.4g}",
            "accelerometer_gain": f"{belief.gain:.4g}",
            "stick_limit_uncertainty": f"{std[0]:.3g}",
            "slip_deceleration_uncertainty": f"{std[1]:.3g}",
            "transits_used": str(belief.transits),
            "operator_speeds_used": str(belief.operator_speeds),
            "operating_points": str(len(belief.points)),
            "measurements_refused": str(self._refused),
            "transits_waiting_for_samples": str(self._source.waiting),
            "file": self._file or "(none)",
        }
        return diagnostic_status(name, level, text, "part model", values)
