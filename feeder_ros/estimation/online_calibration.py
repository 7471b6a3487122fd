"""Turns what a running cell measures into calibration measurements (ROS-free core of the
vehicle estimator node's calibration).

* **Sensor transits** (``parts/sensor_events``): the rising edges of two part-present sensors are
  paired into transits (:class:`~feeder_ros.sensors.transits.TransitTimer`). A transit counts only
  when the whole passage lies after the estimator's carrier model converged at the current drive
  setting (:attr:`~feeder_ros.estimation.vehicle_estimator.VehicleEstimator.steady_since_s`): a
  part that began its passage under the previous setting or its ramp was carried at another speed.
  Its uncertainty: ``transit_uncertainty`` relative (part-to-part variation, sensor jitter) and
  the timing's quantisation, about one response period in the transit's duration (a part moves in
  steps once per period), uniform: ``period/(T*sqrt(3))`` relative. The sensor edges can arrive
  ahead of the accelerometer samples of the same moment (another topic; on a loaded machine the
  estimator drains its samples late): a transit ending after the samples the estimator has seen
  waits (:meth:`MeasurementSource.due`, called as the samples come in) and is refused, with the
  lag, only when the stream falls more than :data:`MAX_STREAM_LAG_S` behind the sensors.
* **An operator's measured speed**, with its uncertainty (default 2 %), at the current setting.

Each gives a :class:`~feeder_ros.estimation.calibration.SpeedMeasurement` on the estimator's
current carrier model, or the reason it cannot be used (an edge from a sensor index or position the
configuration does not have, a transit that is not positive or impossibly fast, the estimator
settling, a speed that is NaN or infinite).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from feeder_ros.estimation.calibration import SpeedMeasurement
from feeder_ros.estimation.vehicle_estimator import VehicleEstimator
from feeder_ros.physics.parameters import ParameterError, is_number
from feeder_ros.sensors.transits import Transit, TransitTimer

__all__ = ["MeasurementSource"]

#: a sensor event's position may differ from the configured one by this much (rounding)
POSITION_TOLERANCE_M = 1e-3
#: a transit may end this long after the accelerometer samples the estimator has seen
STREAM_SLACK_S = 0.5
#: a transit waits for the accelerometer stream at most this long (sensor time) behind the sensors
MAX_STREAM_LAG_S = 10.0
#: transits waiting for the stream at most (the oldest is refused beyond)
MAX_WAITING_TRANSITS = 64
DEFAULT_OPERATOR_UNCERTAINTY = 0.02


class MeasurementSource:
    """Pairs sensor edges into transits and checks measurements against the estimator's state.

    ``sensor_positions_m``: the track positions of the part-present sensors, by index (the
    simulator's ``sensor_positions_m``); ``transit_sensors``: the two timed; an empty position
    list means no transit calibration."""

    def __init__(
        self,
        sensor_positions_m: Sequence[float],
        transit_sensors: tuple[int, int] = (0, 1),
        transit_uncertainty: float = 0.01,
    ) -> None:
        positions = tuple(float(p) for p in sensor_positions_m)
        if any(not math.isfinite(p) for p in positions):
            raise ParameterError(f"sensor_positions_m={positions!r} must be finite")
        if not (is_number(transit_uncertainty) and 0.0 < transit_uncertainty < 1.0):
            raise ParameterError(f"transit_uncertainty={transit_uncertainty!r} must be in (0, 1)")
        self.positions = positions
        self.transit_uncertainty = float(transit_uncertainty)
        self.timer: TransitTimer | None = None
        self._waiting: list[Transit] = []  # complete transits the stream has not reached yet
        self._latest_edge_s = -math.inf
        first, second = transit_sensors
        if positions:
            for index in (first, second):
                if not 0 <= index < len(positions):
                    raise ParameterError(
                        f"transit sensor {index} does not exist: {len(positions)} sensors "
                        f"configured ({positions})"
                    )
            distance = positions[second] - positions[first]
            if distance <= 0.0:
                raise ParameterError(
                    f"transit sensors {first} -> {second} are {distance:g} m apart: the second "
                    "must lie downstream of the first"
                )
            self.timer = TransitTimer(first, second, distance)

    def on_sensor_edge(
        self,
        estimator: VehicleEstimator,
        stamp_s: float,
        sensor: int,
        position_m: float,
        part: int | None,
        present: bool,
    ) -> SpeedMeasurement | str | None:
        """The measurement a sensor edge completes, the reason it is refused, or None."""
        if self.timer is None:
            return None
        if not 0 <= sensor < len(self.positions):
            return (
                f"sensor event from sensor {sensor}, but {len(self.positions)} sensors are "
                f"configured ({self.positions}): ignored"
            )
        expected = self.positions[sensor]
        if not (math.isfinite(position_m) and abs(position_m - expected) <= POSITION_TOLERANCE_M):
            return (
                f"sensor {sensor} reports position {position_m!r} m, configured {expected:g} m: "
                "the sensor list does not match this feeder; ignored"
            )
        self._latest_edge_s = stamp_s
        transit = self.timer.on_edge(stamp_s, sensor, part, present)
        if transit is None:
            refusal, self.timer.last_refusal = self.timer.last_refusal, ""
            return refusal or None
        if transit.end_s > estimator.last_estimate.t_s + STREAM_SLACK_S:
            self._waiting.append(transit)  # measured by due() once the samples are in
            if len(self._waiting) > MAX_WAITING_TRANSITS:
                return self._stream_lags(estimator, self._waiting.pop(0))
            return None
        return self._transit_measurement(estimator, transit)

    @property
    def waiting(self) -> int:
        """Transits complete at the sensors, waiting for the accelerometer stream."""
        return len(self._waiting)

    def due(self, estimator: VehicleEstimator) -> list[SpeedMeasurement | str]:
        """The waiting transits the estimator's samples now reach (measured, or refused by the
        steady-segment rule), and those the stream lags more than :data:`MAX_STREAM_LAG_S`
        behind the sensors (refused with the lag); in the transits' order."""
        reached = estimator.last_estimate.t_s
        outcomes: list[SpeedMeasurement | str] = []
        keep = []
        for transit in self._waiting:
            if transit.end_s <= reached + STREAM_SLACK_S:
                outcomes.append(self._transit_measurement(estimator, transit))
            elif self._latest_edge_s - transit.end_s > MAX_STREAM_LAG_S:
                outcomes.append(self._stream_lags(estimator, transit))
            else:
                keep.append(transit)
        self._waiting = keep
        return outcomes

    def _stream_lags(self, estimator: VehicleEstimator, transit: Transit) -> str:
        return (
            f"transit ending at {transit.end_s:.3f} s not used: the accelerometer stream has "
            f"reached only {estimator.last_estimate.t_s:.3f} s, more than "
            f"{MAX_STREAM_LAG_S:g} s behind the sensors ({self._latest_edge_s:.3f} s)"
        )

    def _transit_measurement(
        self, estimator: VehicleEstimator, transit: Transit
    ) -> SpeedMeasurement | str:
        fit = estimator.fit
        steady = estimator.steady_since_s
        if fit is None or not math.isfinite(steady) or transit.start_s < steady:
            when = f"since {steady:.3f} s" if math.isfinite(steady) else "not yet"
            return (
                f"transit {transit.start_s:.3f}-{transit.end_s:.3f} s not used: the carrier was "
                f"not steady at one drive setting for all of it (steady {when})"
            )
        if transit.end_s > estimator.last_estimate.t_s + STREAM_SLACK_S:
            return (
                f"transit ending at {transit.end_s:.3f} s not used: the accelerometer stream has "
                f"reached only {estimator.last_estimate.t_s:.3f} s"
            )
        period = 1.0 / fit.base_frequency_hz
        speed = transit.speed_mps
        sigma = speed * math.hypot(
            self.transit_uncertainty, period / (transit.duration_s * math.sqrt(3.0))
        )
        return SpeedMeasurement(fit, speed, sigma, "transit", _drive(estimator))

    def operator_speed(
        self, estimator: VehicleEstimator, speed_mps: float, uncertainty_mps: float
    ) -> SpeedMeasurement | str:
        """An operator's measured speed now, or why it cannot be used."""
        if not (is_number(speed_mps) and math.isfinite(speed_mps)):
            return f"speed_mps={speed_mps!r} is not a finite number"
        if not (is_number(uncertainty_mps) and math.isfinite(uncertainty_mps)):
            return f"uncertainty_mps={uncertainty_mps!r} is not a finite number"
        if uncertainty_mps < 0.0:
            return f"uncertainty_mps={uncertainty_mps!r} is negative"
        fit = estimator.fit
        if fit is None or not math.isfinite(estimator.steady_since_s):
            return (
                "the estimator is settling (no converged carrier model at the current drive "
                "setting): measure again once the feeder runs steadily"
            )
        sigma = uncertainty_mps or DEFAULT_OPERATOR_UNCERTAINTY * abs(speed_mps)
        return SpeedMeasurement(fit, speed_mps, sigma, "operator", _drive(estimator))


def _drive(estimator: VehicleEstimator) -> tuple[float, float]:
    command = estimator.drive_command
    if command is not None:
        return command
    return (estimator.drive_frequency_hz, math.nan)
