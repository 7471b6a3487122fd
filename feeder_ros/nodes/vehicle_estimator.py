"""``vehicle_estimator``: a part's speed and stick/slip phase from the carrier accelerometer alone.

The paper's sensorless idea as a node: accelerometer samples (``imu``, or ``imu/batch`` for
high-rate streams) and, when available, the drive command go into the ROS-free
:class:`~feeder_ros.estimation.vehicle_estimator.VehicleEstimator`; its records come out as
``feeder_ros/VehicleEstimate`` on ``estimate`` at ``publish_rate_hz`` and as ``/diagnostics``.
Callbacks only queue samples; the estimation runs in the publish timer, in batches.

Without a drive command the drive frequency is taken from the accelerometer spectrum, searched
between ``min_drive_frequency_hz`` and ``max_drive_frequency_hz``. A carrier that answers at a
subharmonic (a period of several drive periods) can have its strongest line below the drive
frequency, so set the band to the drive's frequency range.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu

from feeder_ros.estimation.estimator_records import input_health
from feeder_ros.estimation.vehicle_estimator import VehicleEstimate as EstimateRecord
from feeder_ros.estimation.vehicle_estimator import load_kernels
from feeder_ros.msg import AccelerometerBatch, CarrierState, DriveCommand, VehicleEstimate
from feeder_ros.nodes.diagnostics import diagnostic_array, diagnostic_status
from feeder_ros.nodes.estimator_calibration import EstimatorCalibration
from feeder_ros.nodes.ros_parameters import declare_parameters, validator
from feeder_ros.nodes.ros_time import stamp_seconds
from feeder_ros.nodes.runner import run_node
from feeder_ros.nodes.stall_detector import StallDetector
from feeder_ros.nodes.vehicle_estimator_parameters import (
    AXES,
    DEFAULTS,
    INTERFACE,
    PARAMETERS,
    build_estimator,
    check_combination,
    nominal_part,
)

if TYPE_CHECKING:
    from feeder_ros.ros_compat import AnyParameter

DIAGNOSTICS_PERIOD_S = 1.0  # the diagnostics timer's period (a later tick: the node stalled)
#: an accelerometer batch with a longer sample period is refused (the estimator needs a fast
#: accelerometer; a period in ns or ms sent as seconds would put stamps far in the future)
MAX_SAMPLE_PERIOD_S = 1.0
SENSOR_QOS = QoSProfile(depth=500, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

_IMU_AFTER_HEADER = 8 * (4 + 9 + 3 + 9)  # orientation, its covariance, angular velocity, its cov.


_IMU_DRAIN_LIMIT = 200  # Imu messages taken per callback beyond the one delivered


def imu_sample(data: bytes) -> tuple[float, tuple[float, float, float]]:
    """(stamp in s, linear acceleration x, y, z) of a CDR-serialised sensor_msgs/Imu.

    Reads the three fields straight from the bytes (XCDR1, either byte order): the header's
    frame_id is the only variable-length field, and everything after it is 8-byte aligned.
    """
    if len(data) < 16 or data[0] != 0 or data[1] not in (0, 1):
        raise ValueError(f"not a CDR message (encapsulation {data[:4].hex()})")
    order = "<" if data[1] == 1 else ">"
    sec, nanosec, length = struct.unpack_from(order + "iII", data, 4)
    position = 16 + length
    position = 4 + ((position - 4 + 7) & ~7)  # align to 8 from the payload start
    end = position + _IMU_AFTER_HEADER + 24
    if length > len(data) or end > len(data):
        raise ValueError(f"truncated Imu message ({len(data)} bytes, frame_id of {length})")
    x, y, z = struct.unpack_from(order + "3d", data, position + _IMU_AFTER_HEADER)
    return sec + nanosec * 1e-9, (x, y, z)


class VehicleEstimatorNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        # before the node joins the graph: a cell waits for it, and its first estimates then
        # come without a stall (see load_kernels)
        loading = time.monotonic()
        load_kernels()
        loaded_s = time.monotonic() - loading
        super().__init__(INTERFACE.node_name, **kwargs)
        self.get_logger().debug(f"estimator kernels loaded in {loaded_s:.2f} s")
        self._values = declare_parameters(self, PARAMETERS.values(), DEFAULTS)
        check_combination(self._values)
        self.add_on_set_parameters_callback(
            validator(PARAMETERS, check_all=check_combination, current=lambda: self._values)
        )
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._lock = threading.Lock()
        #: the last accepted drive command (frequency [Hz], amplitude, stamp [s]): a rebuilt
        #: estimator (a parameter change) starts with it instead of searching for the frequency
        self._drive: tuple[float, float, float] | None = None
        self._estimator = build_estimator(self._values)
        self._queue_t: list[float] = []
        self._queue_value: list[float] = []
        self._batches: list[tuple[np.ndarray, np.ndarray]] = []
        self._received = 0
        self._published_received = 0  # samples received when the last estimate went out
        self._last_input = self.get_clock().now()
        # after this process's own stall (a late diagnostics tick), silence counts from the end
        # of the middleware's catch-up: the samples sent meanwhile are on their way
        self._stalls = StallDetector(DIAGNOSTICS_PERIOD_S, start_s=time.monotonic())
        self._listening_since = self._last_input
        self._record: EstimateRecord = self._estimator.last_estimate
        self._axis = AXES.index(self._values["imu_axis"])
        self._calibration = EstimatorCalibration(
            self, self._lock, lambda: self._estimator, nominal_part(self._values), self._values
        )
        self._estimator.set_belief(self._calibration.belief)  # e.g. read from the file

        self._publisher = self.create_publisher(VehicleEstimate, "estimate", 10)
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        if self._values["use_carrier_state"]:
            self.create_subscription(CarrierState, "carrier/state", self._on_state, RELIABLE_QOS)
        else:
            # raw: at 1 kHz, building an Imu object per sample costs more than the estimate
            # best effort by default (matches any sensor driver); qos_overrides parameters,
            # e.g. `qos_overrides./feeder/imu.subscription.reliability:=reliable`, change it
            overridable = QoSOverridingOptions.with_default_policies()
            self._imu_subscription = self.create_subscription(
                Imu, "imu", self._on_imu, SENSOR_QOS, raw=True, qos_overriding_options=overridable
            )
            self.create_subscription(
                AccelerometerBatch,
                "imu/batch",
                self._on_batch,
                SENSOR_QOS,
                qos_overriding_options=overridable,
            )
        self.create_subscription(DriveCommand, "drive/command", self._on_command, COMMAND_QOS)
        self.create_timer(1.0 / self._values["publish_rate_hz"], self._estimate)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)

    # -- parameters ----------------------------------------------------------------------------
    def _apply_parameters(self, parameters: list[AnyParameter]) -> None:
        changed = False
        for parameter in parameters:
            if parameter.name in PARAMETERS:
                self._values[parameter.name] = parameter.value
                changed = True
        if changed:
            with self._lock:  # a new nominal part or window: start over
                nominal = nominal_part(self._values)
                if nominal != self._calibration.belief.nominal:
                    self._calibration.renominate(nominal)
                self._estimator = build_estimator(self._values, self._calibration.belief)
                if self._drive is not None:  # the drive in force is still in force
                    self._estimator.set_drive(*self._drive)
                self._record = self._estimator.last_estimate

    # -- inputs (queue only) -------------------------------------------------------------------
    def _on_imu(self, data: bytes) -> None:
        samples = [data, *self._waiting_imu_messages()]
        with self._lock:
            for raw in samples:
                try:
                    stamp_s, acceleration = imu_sample(raw)
                except ValueError as error:
                    self.get_logger().warning(
                        f"ignoring Imu message: {error}", throttle_duration_sec=5.0
                    )
                    continue
                self._queue_t.append(stamp_s)
                self._queue_value.append(acceleration[self._axis])

    def _waiting_imu_messages(self) -> list[bytes]:
        """The Imu messages already waiting behind the one being handled.

        A feeder's samples arrive in bursts (one per controller tick); rclpy's executor would
        spend a whole wait-set cycle on each, which at 1 kHz costs more than the estimate.
        Taking the burst here, the way the executor takes one message, keeps the samples in
        order and nothing is lost (at most ``_IMU_DRAIN_LIMIT`` per callback, so the other
        callbacks are served in between).
        """
        taken: list[bytes] = []
        handle = self._imu_subscription.handle
        try:
            with handle:
                while len(taken) < _IMU_DRAIN_LIMIT:
                    message_info = handle.take_message(Imu, True)
                    if message_info is None:
                        break
                    taken.append(message_info[0])
        except InvalidHandle:  # the node is being destroyed (shutdown): as the executor does
            pass
        return taken

    def _on_batch(self, message: AccelerometerBatch) -> None:
        columns = (
            message.acceleration_x_mps2,
            message.acceleration_y_mps2,
            message.acceleration_z_mps2,
        )
        values = np.asarray(columns[self._axis], dtype=np.float64)
        period = message.sample_period_s
        if not (0.0 < period <= MAX_SAMPLE_PERIOD_S) or values.size == 0:  # False for nan
            self.get_logger().warning(
                f"ignoring accelerometer batch: sample_period_s={period!r} (0 < period <= "
                f"{MAX_SAMPLE_PERIOD_S:g} s), {values.size} samples",
                throttle_duration_sec=5.0,
            )
            return
        t = stamp_seconds(message.header.stamp) + period * np.arange(values.size)
        with self._lock:
            self._batches.append((t, values))

    def _on_state(self, message: CarrierState) -> None:
        with self._lock:
            self._queue_t.append(stamp_seconds(message.header.stamp))
            self._queue_value.append(message.displacement_m)

    def _on_command(self, message: DriveCommand) -> None:
        frequency = message.frequency_hz
        if not (math.isfinite(frequency) and frequency > 0.0):
            self.get_logger().warning(
                f"ignoring drive command with frequency_hz={frequency!r}",
                throttle_duration_sec=5.0,
            )
            return
        amplitude = message.amplitude_n if message.enabled else 0.0
        with self._lock:
            if self._drive is not None and self._drive[:2] == (frequency, amplitude):
                # a drive re-sends its set point (50 Hz in the demo cell): nothing changes, and
                # draining here would take the samples the estimate timer publishes from
                return
            self._drain()  # samples before the command belong to the previous drive
            drive = (frequency, amplitude, stamp_seconds(message.header.stamp))
            try:
                self._estimator.set_drive(*drive)
            except ValueError as error:
                self.get_logger().warning(f"ignoring drive command: {error}")
            else:
                self._drive = drive

    # -- estimation ----------------------------------------------------------------------------
    def _drain(self) -> None:
        """Feed queued samples to the estimator (caller holds the lock)."""
        chunks = list(self._batches)
        if self._queue_t:
            chunks.append((np.asarray(self._queue_t), np.asarray(self._queue_value)))
        self._batches, self._queue_t, self._queue_value = [], [], []
        if not chunks:
            return
        chunks.sort(key=lambda chunk: float(chunk[0][0]))
        t = np.concatenate([c[0] for c in chunks])
        values = np.concatenate([c[1] for c in chunks])
        self._received += t.size
        self._last_input = self.get_clock().now()
        if self._values["use_carrier_state"]:
            self._record = self._estimator.push_carrier_state(t, values)
        else:
            self._record = self._estimator.push(t, values)

    def _estimate(self) -> None:
        with self._lock:
            self._drain()
            # samples drained by a drive command since the last tick count too: publish whenever
            # the estimate has advanced, whoever fed it
            if self._received == self._published_received:
                return
            self._published_received = self._received
            record = self._record
        self._publisher.publish(self._to_message(record))
        self._calibration.stream_advanced()

    def _to_message(self, record: EstimateRecord) -> VehicleEstimate:
        message = VehicleEstimate()
        # no stamp (0) before the first sample, nor for a time a stamp cannot hold (int32 s)
        if 0.0 <= record.t_s < 2.0**31 - 1.0:
            seconds = math.floor(record.t_s)
            message.header.stamp.sec = int(seconds)
            message.header.stamp.nanosec = min(round((record.t_s - seconds) * 1e9), 999_999_999)
        message.header.frame_id = "track"
        for name in (
            "carrier_velocity_mps",
            "part_velocity_mps",
            "part_velocity_uncertainty_mps",
            "part_velocity_confidence",
            "phase_confidence",
            "advance_per_cycle_m",
            "advance_per_cycle_confidence",
            "slip_fraction",
            "slip_fraction_confidence",
            "mean_speed_mps",
            "mean_speed_uncertainty_mps",
            "mean_speed_confidence",
            "window_s",
        ):
            setattr(message, name, float(getattr(record, name)))
        message.phase = int(record.phase)
        message.status = int(record.status)
        message.status_message = record.status_message
        return message

    def _publish_diagnostics(self) -> None:
        with self._lock:
            record = self._record
            now = self.get_clock().now()
            if self._stalls.resuming(time.monotonic()):
                # the catch-up runs on the wall clock, silence on the node clock (maybe a
                # faster simulation's): listening from every tick within the catch-up
                self._listening_since = now
            since = max(self._last_input, self._listening_since)
            silent_s = (now - since).nanoseconds * 1e-9
            waited_s = (now - self._last_input).nanoseconds * 1e-9  # since start, if none came
            received = self._received
        level, text = input_health(
            received,
            silent_s,
            waited_s,
            self._values["startup_timeout_s"],
            self._values["input_timeout_s"],
            record.status,
            record.status_message,
        )
        values = {
            "status": record.status.name,
            "status_message": record.status_message,
            "samples_received": str(received),
            "drive_frequency_hz": f"{record.drive_frequency_hz:.4g}",
            "mean_speed_mps": f"{record.mean_speed_mps:.6g}",
            "mean_speed_uncertainty_mps": f"{record.mean_speed_uncertainty_mps:.3g}",
            "mean_speed_confidence": f"{record.mean_speed_confidence:.3f}",
            "slip_fraction": f"{record.slip_fraction:.4g}",
            **self._stalls.diagnostic_values(),
        }
        name = self.get_fully_qualified_name()
        status = diagnostic_status(
            f"{name}: estimate", level, text, "carrier accelerometer", values
        )
        part_model = self._calibration.diagnostic_status(f"{name}: part model")
        array = diagnostic_array(self.get_clock().now().to_msg(), status, part_model)
        self._diagnostics.publish(array)

    def destroy_node(self) -> None:
        self._calibration.close()  # its worker thread publishes no more on a destroyed node
        super().destroy_node()  # type: ignore[no-untyped-call,unused-ignore]  # untyped on Jazzy


NODE_CLASS = VehicleEstimatorNode


def main(args: list[str] | None = None) -> int:
    return run_node(VehicleEstimatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
