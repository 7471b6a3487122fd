"""The drive interface's vibration-amplitude regulation: hold the carrier's measured vibration.

The inner loop of an industrial feeder controller: the accelerometer's line at the drive
frequency (``amplitude.imu_topic``, x along the track) is held at a set point by moving the drive
amplitude. Measuring and the control law are the ROS-free core
:mod:`feeder_ros.drive.amplitude_regulator`; this shell feeds it the samples and the drive's
output, and applies its amplitude through
:meth:`DriveController.set_drive` (frequency kept, the drive's ramp-rate limits and
``max_amplitude_percent`` still the outer bounds).

- **How it acts**: through :meth:`DriveController.scale_amplitude`, a correction of the output
  amplitude (slewed at the drive's amplitude rate limit, the output clamped to
  ``max_amplitude_percent``). The set point stays the one set_drive or the speed loops wrote: it is
  the starting point, and the loop scales the output from it to hold the line.
- **When it acts**: ``amplitude.enabled``, the drive started and its output on, not paused, no
  fault or e-stop latched, and the drive at its set point once (the loop takes over there).
  Otherwise the line and the gain are reset and measured afresh; an output that goes off
  forgets the correction (the next start begins at the set point). Switched off, or with no line
  to hold, the correction returns to 1 at the drive's ramp rate.
- **Set point, outside target-speed mode**: ``amplitude.set_point_mps2`` (NaN: none; then it only
  measures) or the ``set_vibration_amplitude`` service, which sets that parameter. Refused, with
  the value and the reachable range, when not finite, not > 0, or beyond
  ``max_amplitude_percent`` times the gain measured at the drive frequency (before a measurement
  the reach is unknown: accepted, and a set point out of reach holds the drive at its limit, said
  in ``/diagnostics``).
- **In target-speed mode it is the inner loop of the speed loops** (the speed model, the speed
  trim, resonance tracking): they keep writing the amplitude set point in %, and the loop holds
  the line that % gave when it took over: the gain measured then (m/s^2 per % of set point, at
  that frequency) times the set point. A spring or load change is taken out within seconds, so
  the speed loops see the feeder they were tuned on; a new frequency (a new target, the tracker's
  dither) takes a new reference there, which leaves slow drifts to the tracker. The
  ``amplitude.set_point_mps2`` is not used (a set point is refused) until target-speed mode ends.
- **Clocks**: the samples' stamps and the drive's outputs (node clock) must share a clock (sim
  time or wall time on both); samples stamped far ahead are dropped with a warning.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

from feeder_ros.drive.amplitude_regulator import (
    AmplitudeMeasurement,
    AmplitudeRegulator,
    LineAmplitude,
    RegulatorOutput,
)
from feeder_ros.drive.resonance_tracker import FUTURE_STAMP_TOLERANCE_S
from feeder_ros.msg import AccelerometerBatch
from feeder_ros.nodes.drive_interface_parameters import (
    ENABLED,
    SET_POINT,
    amplitude_settings_from,
)
from feeder_ros.nodes.ros_time import stamp_seconds
from feeder_ros.srv import SetVibrationAmplitude

if TYPE_CHECKING:
    from rclpy.node import Node

    from feeder_ros.drive.backend import DriveOutput
    from feeder_ros.drive.controller import DriveController
    from feeder_ros.msg import DriveState as DriveStateMsg
    from feeder_ros.ros_compat import AnyParameter

__all__ = [
    "IMU_QOS",
    "AmplitudeShell",
    "set_point_refusal",
]

#: the accelerometer stream: best effort as published; deep enough for a busy executor
IMU_QOS = QoSProfile(depth=500, reliability=ReliabilityPolicy.BEST_EFFORT)
#: target-speed mode: steady windows averaged into the reference (one scatters by 1-3 %)
REFERENCE_WINDOWS = 3
#: the drive's outputs kept beyond the longest window (a window's end arrives this late at most)
HISTORY_MARGIN_S = 2.0


def set_point_refusal(value: float, reach: float | None, frequency_hz: float, top: float) -> str:
    """Why ``value`` [m/s^2] cannot be the set point ('' if it can), naming the reachable range:
    ``reach`` is the line at ``top`` % measured at ``frequency_hz`` (None: not measured yet)."""
    limit = reach if reach is not None and math.isfinite(reach) else math.inf
    where = (
        f"reachable 0 .. {limit:.4g} m/s^2 at {frequency_hz:g} Hz (max_amplitude_percent {top:g})"
        if math.isfinite(limit)
        else "reach not measured yet (it is while regulating)"
    )
    if not math.isfinite(value):
        return f"amplitude set point {value!r} m/s^2 is not a finite number; {where}"
    if value <= 0.0:
        return f"amplitude set point {value:g} m/s^2 must be > 0; {where}"
    if value > limit:
        return f"amplitude set point {value:g} m/s^2 beyond the drive's reach: {where}"
    return ""


class _Outputs:
    """The drive's recent outputs by time (node clock): what it applied at a window's end."""

    def __init__(self, size: int) -> None:
        self._items: deque[DriveOutput] = deque(maxlen=max(2, size))

    def record(self, output: DriveOutput) -> None:
        if not self._items or output.time_s > self._items[-1].time_s:
            self._items.append(output)

    def at(self, t_s: float) -> DriveOutput | None:
        """The output in force at ``t_s`` (the latest for later times; None before the oldest)."""
        index = bisect.bisect_right(self._items, t_s, key=lambda output: output.time_s)
        return self._items[index - 1] if index else None


class AmplitudeShell:
    """Vibration-amplitude regulation for ``node`` (a DriveInterface; ``values``: its parameter
    dict, kept current by the node). Creates the ``set_vibration_amplitude`` service and a
    parameter check for the set point; subscribes to the accelerometer at configure."""

    def __init__(self, node: Node, values: dict[str, Any]) -> None:
        self._node, self._values = node, values
        self._controller: DriveController | None = None
        self._line: LineAmplitude | None = None
        self._regulator: AmplitudeRegulator | None = None
        self._outputs = _Outputs(2)
        self._sub: Any = None
        self._t: list[float] = []  # samples received since the last tick
        self._a: list[float] = []
        self._set_point = math.nan
        self._engaged_s: float | None = None  # since when the loop owns the amplitude
        self._speed_mode = False  # target-speed mode when last ticked
        self._reference: tuple[float, float] | None = None  # m/s^2 per set-point %, at Hz
        self._holding = math.nan  # the line held at the latest tick [m/s^2] (NaN: none)
        self._reference_gains: list[tuple[float, float]] = []  # toward the next reference
        self._fed_until = -math.inf
        self._measurement: AmplitudeMeasurement | None = None
        self._output: RegulatorOutput | None = None
        self._now = -math.inf
        self._note = "not configured"
        self._service = node.create_service(
            SetVibrationAmplitude, "set_vibration_amplitude", self._on_set_amplitude
        )
        node.add_on_set_parameters_callback(self._check_parameters)
        node.add_post_set_parameters_callback(self._on_parameters)

    # -- lifecycle ---------------------------------------------------------------------------------
    def configure(self, controller: DriveController) -> None:
        values, limits = self._values, controller.limits
        settings = amplitude_settings_from(values)
        self._controller = controller
        self._line = LineAmplitude(settings)
        self._regulator = AmplitudeRegulator(settings, limits.max_amplitude_percent)
        horizon_s = settings.window_s(limits.min_frequency_hz) + HISTORY_MARGIN_S
        self._outputs = _Outputs(math.ceil(horizon_s * values["publish_rate_hz"]))
        batches = values["amplitude.imu_type"] == "imu_batch"
        self._sub = self._node.create_subscription(
            AccelerometerBatch if batches else Imu,
            values["amplitude.imu_topic"],
            self._on_batch if batches else self._on_imu,
            IMU_QOS,
        )
        self._set_point = float(values[SET_POINT])
        self._disengage("waiting for the drive to run")

    def teardown(self) -> None:
        if self._sub is not None:
            self._node.destroy_subscription(self._sub)
            self._sub = None
        self._disengage("not configured")
        self._controller = self._line = self._regulator = None

    def destroy(self) -> None:
        self._node.destroy_service(self._service)

    # -- inputs ------------------------------------------------------------------------------------
    def _on_imu(self, message: Imu) -> None:
        if self._engaged_s is not None:
            stamp = message.header.stamp
            self._t.append(stamp_seconds(stamp))
            self._a.append(float(message.linear_acceleration.x))

    def _on_batch(self, message: AccelerometerBatch) -> None:
        if self._engaged_s is None or not message.acceleration_x_mps2:
            return
        period = float(message.sample_period_s)
        if not (math.isfinite(period) and period > 0.0):
            self._node.get_logger().warning(
                f"{self._values['amplitude.imu_topic']}: sample_period_s={period!r}: batch "
                "ignored by amplitude regulation",
                throttle_duration_sec=5.0,
            )
            return
        start = stamp_seconds(message.header.stamp)
        samples = np.asarray(message.acceleration_x_mps2, dtype=np.float64)
        self._t.extend((start + period * np.arange(samples.size)).tolist())
        self._a.extend(samples.tolist())

    def _check_parameters(self, parameters: list[AnyParameter]) -> SetParametersResult:
        """A set point the service would refuse is refused as a parameter too (NaN clears it)."""
        for parameter in parameters:
            value = parameter.value
            if parameter.name != SET_POINT or not isinstance(value, float) or math.isnan(value):
                continue
            reason = self._refusal(value) if self._controller is not None else ""
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_parameters(self, parameters: list[AnyParameter]) -> None:
        for parameter in parameters:
            if parameter.name == SET_POINT:
                self._set_point = float(parameter.value)
                if self._regulator is None or self._speed_mode:
                    continue
                if math.isnan(self._set_point):
                    self._disengage("set point cleared: measuring again")
                else:
                    self._regulator.set_point(self._set_point, self._reach())

    def _on_set_amplitude(
        self, request: SetVibrationAmplitude.Request, response: SetVibrationAmplitude.Response
    ) -> Any:
        value = float(request.amplitude_mps2)
        reach = self._reach()
        response.reachable_max_mps2 = math.nan if reach is None else reach
        reason = self._refusal(value)
        if not reason:
            result = self._node.set_parameters([Parameter(SET_POINT, value=value)])[0]
            reason = "" if result.successful else result.reason
        response.result = (
            SetVibrationAmplitude.Response.REFUSED
            if reason
            else SetVibrationAmplitude.Response.ACCEPTED
        )
        response.reason = reason or (
            "" if self._values[ENABLED] else "set point stored; amplitude.enabled is false"
        )
        return response

    def _reach(self) -> float | None:
        regulator, controller = self._regulator, self._controller
        if regulator is None or controller is None:
            return None
        return regulator.reachable_max_mps2(controller.set_point.frequency_hz)

    def _refusal(self, value: float) -> str:
        controller = self._controller
        if controller is None:
            return "drive interface not configured (lifecycle: configure, then activate)"
        if controller.speed_mode:
            return (
                "in target-speed mode the speed loops give the line to hold (their amplitude "
                "times the gain at takeover): set_drive first"
            )
        return set_point_refusal(
            value,
            self._reach(),
            controller.set_point.frequency_hz,
            controller.limits.max_amplitude_percent,
        )

    # -- the loop (before the controller's tick) ---------------------------------------------------
    def tick(self, controller: DriveController, now_s: float, last: DriveOutput) -> None:
        self._now = now_s
        self._outputs.record(last)
        if self._regulator is None:
            return
        self._regulator.max_amplitude_percent = float(controller.limits.max_amplitude_percent)
        if controller.speed_mode != self._speed_mode:
            self._speed_mode = controller.speed_mode
            self._disengage(f"target-speed mode {'on' if self._speed_mode else 'off'}")
        blocker = self._blocker(controller, last)
        if blocker:
            if not self._values[ENABLED]:
                controller.scale_amplitude(1.0)
            self._disengage(blocker)
            return
        if self._engaged_s is None:
            if not controller.ramp.done(now_s):
                self._note = "waiting for the drive to reach its set point"
                return
            self._engaged_s = now_s  # the set point reached: the loop takes over
        if not self._speed_mode and math.isnan(self._set_point):
            controller.scale_amplitude(1.0)  # measuring only
        self._measure(controller, now_s, last)
        self._holding = self._target_line(controller)

    def _blocker(self, controller: DriveController, last: DriveOutput) -> str:
        """Why the loop may not act now ('' when it may)."""
        if not self._values[ENABLED]:
            return "off: amplitude.enabled is false"
        if controller.latched is not None:
            return f"off: latched ({controller.fault_reason})"
        if not controller.running:
            return "off: drive not started"
        if controller.paused:
            return f"off: feeding paused ({controller.hold_reason})"
        return "" if last.enabled else "off: output off"

    def _disengage(self, note: str) -> None:
        """Forget the partial window, the gain, the reference and the samples (the set point
        stays; the correction in force too, until the output goes off)."""
        if self._regulator is not None and self._line is not None:
            self._regulator.reset()
            self._line.reset()
            if math.isfinite(self._set_point) and not self._speed_mode:
                self._regulator.set_point(self._set_point, None)
        self._engaged_s = self._reference = None
        self._reference_gains = []
        self._holding = math.nan
        self._t, self._a = [], []
        self._fed_until = -math.inf
        self._measurement = self._output = None
        self._note = note

    def _take_reference(self, gain: float | None, scale: float, m: AmplitudeMeasurement) -> None:
        """Target-speed mode: the line per set-point % (the measured gain times the correction
        in force), averaged over REFERENCE_WINDOWS steady windows at one frequency."""
        assert self._output is not None
        gains = self._reference_gains
        if gains and not math.isclose(gains[0][1], m.frequency_hz):
            gains.clear()
        self._reference = None
        if gain is None or not self._output.steady:
            return
        gains.append((gain * scale, m.frequency_hz))
        if len(gains) >= REFERENCE_WINDOWS:
            self._reference = (float(np.mean([g for g, _ in gains])), m.frequency_hz)
            gains.clear()

    def _target_line(self, controller: DriveController) -> float:
        """The line the loop holds [m/s^2] (NaN: none)."""
        if not self._speed_mode:
            return self._set_point
        if self._reference is None:
            return math.nan
        return self._reference[0] * controller.set_point.amplitude_percent

    def _measure(self, controller: DriveController, now_s: float, last: DriveOutput) -> None:
        assert self._line is not None
        assert self._engaged_s is not None
        t, a = np.asarray(self._t), np.asarray(self._a)
        self._t, self._a = [], []
        ahead = t > now_s + FUTURE_STAMP_TOLERANCE_S
        if ahead.any():
            self._node.get_logger().warning(
                f"amplitude regulation: {np.count_nonzero(ahead)} accelerometer samples stamped "
                f"over {FUTURE_STAMP_TOLERANCE_S:g} s ahead of this node's clock ignored: do both "
                "nodes use the same clock (use_sim_time)?",
                throttle_duration_sec=5.0,
            )
        keep = (t >= self._engaged_s) & (t > self._fed_until) & ~ahead
        t, first = np.unique(t[keep], return_index=True)  # sorted, each time once
        if t.size == 0:
            return
        self._fed_until = float(t[-1])
        for measurement in self._line.add(t, a[keep][first], last.frequency_hz):
            self._update(controller, now_s, measurement)

    def _update(self, controller: DriveController, now_s: float, m: AmplitudeMeasurement) -> None:
        regulator = self._regulator
        assert regulator is not None
        applied = self._outputs.at(m.t_s)
        if applied is None or not applied.enabled:
            return  # the drive's output then is no longer known (or was off): no use
        self._measurement = m
        self._output = regulator.update(m, applied.amplitude_percent)
        nominal = controller.set_point.amplitude_percent
        if self._speed_mode:
            gain = regulator.gain_at(m.frequency_hz)
            reference = self._reference
            if reference is None or not math.isclose(reference[1], m.frequency_hz):
                self._take_reference(gain, controller.amplitude_scale, m)
            line = self._target_line(controller)
            if math.isfinite(line) and line > 0.0:
                regulator.set_point(line, None)
        if math.isnan(self._target_line(controller)) or nominal <= 0.0:
            return
        if controller.ramp.done(now_s):  # (a ramping set point: its end is not yet the base)
            controller.scale_amplitude(self._output.amplitude_percent / nominal)

    # -- what the node reports ---------------------------------------------------------------------
    def _age_s(self) -> float:
        """Since the latest measurement (or since the loop took over, before the first)."""
        m = self._measurement
        since = m.t_s if m is not None else self._engaged_s
        return math.inf if since is None else self._now - since

    def _fresh(self) -> AmplitudeMeasurement | None:
        regulator = self._regulator
        if regulator is None or not self._age_s() <= regulator.settings.stale_after_s:
            return None
        return self._measurement

    def fill_state(self, message: DriveStateMsg, controller: DriveController) -> None:
        m = self._fresh()
        message.amplitude_regulated = math.isfinite(self._holding)
        message.amplitude_set_point_mps2 = (
            self._holding if self._speed_mode or self._engaged_s is not None else self._set_point
        )
        message.measured_amplitude_mps2 = m.amplitude_mps2 if m is not None else math.nan

    def _summary(self) -> str:
        regulator = self._regulator
        if self._engaged_s is None or regulator is None:
            return self._note
        limit = regulator.settings.stale_after_s
        if not self._age_s() <= limit:
            return (
                f"stale: no measurement for {self._age_s():.3g} s (over amplitude.stale_after_s "
                f"= {limit:g} s): amplitude held"
            )
        if math.isnan(self._holding):
            if self._speed_mode:
                return "under target-speed mode: measuring the gain its amplitude gives"
            return "measuring only (no set point)"
        under = " under target-speed mode" if self._speed_mode else ""
        reason = self._output.reason if self._output is not None else ""
        return f"regulating{under}: {reason}" if reason else f"regulating{under}"

    def warning(self) -> str:
        """Why the loop does not hold its set point now ('' when it does or is not asked to)."""
        if self._engaged_s is None or math.isnan(self._holding) or self._regulator is None:
            return ""
        if not self._age_s() <= self._regulator.settings.stale_after_s:
            return "no amplitude measurement: amplitude held"
        if self._output is not None and self._output.limited:
            return f"at the drive's limit ({self._output.reason or 'set point out of reach'})"
        return ""

    def diagnostics(self) -> dict[str, str]:
        values = {"amplitude regulation": self._summary()}
        regulator = self._regulator
        if regulator is None:
            return values
        m, reach = self._fresh(), self._reach()
        values |= {
            "amplitude feedback": (
                f"{self._node.resolve_topic_name(self._values['amplitude.imu_topic'])} "
                f"({self._values['amplitude.imu_type']})"
            ),
            "amplitude set point m/s^2": f"{self._holding:.4g}"
            if self._engaged_s is not None
            else f"{self._set_point:.4g}",
            "amplitude measured m/s^2": f"{m.amplitude_mps2:.4g}" if m else "none",
            "amplitude residual m/s^2": f"{m.residual_mps2:.4g}" if m else "none",
            "amplitude reach m/s^2": "unknown" if reach is None else f"{reach:.4g}",
            "amplitude limited": str(self._output is not None and self._output.limited),
            "amplitude regulator": regulator.last_note,
        }
        return values
