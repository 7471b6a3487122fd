"""What a cell measures, turned into calibration measurements (pure core): transit pairing, the
steady-segment rule, refusals with their reasons, and the calibration file."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeder_ros.estimation import EstimatorConfig, PartModel, VehicleEstimator
from feeder_ros.estimation.calibration import SpeedMeasurement
from feeder_ros.estimation.calibration_file import (
    CalibrationFileError,
    read_calibration,
    write_calibration,
)
from feeder_ros.estimation.online_calibration import MeasurementSource
from feeder_ros.estimation.part_belief import PartBelief
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.simulation import simulate
from feeder_ros.sensors.transits import TransitTimer

SENSORS = (0.05, 0.135)


@pytest.fixture(scope="module")
def steady_estimator() -> VehicleEstimator:
    """An estimator that has run 6 s at one drive setting (steady since about 1.3 s)."""
    params = FeederParameters(
        damping_ns_per_m=200.0, drive_frequency_hz=22.0, drive_amplitude_n=40.0,
        track_length_m=1e3,
    )  # fmt: skip
    sim = simulate(params, 6.0, 1000.0)
    estimator = VehicleEstimator(EstimatorConfig(part=PartModel()))
    estimator.set_drive(22.0, 40.0, 0.0)
    for k in range(0, sim.t_s.size, 50):
        estimator.push(sim.t_s[k : k + 50], sim.carrier_a_mps2[k : k + 50])
    assert math.isfinite(estimator.steady_since_s)
    return estimator


def test_transits_pair_by_part_id_or_first_in_first_out() -> None:
    timer = TransitTimer(0, 1, 0.085)
    assert timer.on_edge(1.0, 0, 7, True) is None
    assert timer.on_edge(1.5, 0, 8, True) is None
    assert timer.on_edge(1.2, 0, 7, False) is None  # falling edges do not count
    transit = timer.on_edge(9.5, 1, 8, True)  # part 8 first: paired by id
    assert transit is not None
    assert (transit.start_s, transit.end_s, transit.part_id) == (1.5, 9.5, 8)
    assert transit.speed_mps == pytest.approx(0.085 / 8.0)
    anonymous = TransitTimer(0, 1, 0.085)
    for stamp in (1.0, 2.0):
        anonymous.on_edge(stamp, 0, None, True)
    first = anonymous.on_edge(6.0, 1, None, True)
    assert first is not None
    assert first.start_s == 1.0  # first in, first out
    for bad in ((0, 0, 0.085), (0, 1, 0.0), (0, 1, math.nan), (0, 1, -0.01)):
        with pytest.raises(ParameterError):
            TransitTimer(*bad)


@pytest.mark.parametrize(
    ("second_edge", "needle"),
    [(1.0, "took 0 s"), (0.5, "took -0.5 s"), (1.001, "is faster than the carrier can carry")],
)
def test_impossible_transit_times_are_refused_with_the_reason(
    second_edge: float, needle: str
) -> None:
    timer = TransitTimer(0, 1, 0.085, max_speed_mps=1.0)
    timer.on_edge(1.0, 0, 3, True)
    assert timer.on_edge(second_edge, 1, 3, True) is None
    assert needle in timer.last_refusal


def test_a_transit_counts_only_within_one_steady_drive_setting(
    steady_estimator: VehicleEstimator,
) -> None:
    source = MeasurementSource(SENSORS)
    steady = steady_estimator.steady_since_s
    # began before the carrier was steady at this setting: refused, naming the times
    source.on_sensor_edge(steady_estimator, steady - 0.5, 0, 0.05, 1, True)
    refused = source.on_sensor_edge(steady_estimator, steady + 4.0, 1, 0.135, 1, True)
    assert isinstance(refused, str)
    assert "not steady at one drive setting for all of it" in refused
    # wholly after it: a measurement on the estimator's carrier model, its uncertainty the
    # transit spread and the timing's quantisation (one response period in the duration)
    source.on_sensor_edge(steady_estimator, steady + 0.1, 0, 0.05, 2, True)
    measurement = source.on_sensor_edge(steady_estimator, steady + 4.1, 1, 0.135, 2, True)
    assert isinstance(measurement, SpeedMeasurement)
    assert measurement.speed_mps == pytest.approx(0.085 / 4.0)
    assert measurement.fit is steady_estimator.fit
    assert measurement.drive == (22.0, 40.0)
    period = 1.0 / steady_estimator.fit.base_frequency_hz  # type: ignore[union-attr]
    expected = measurement.speed_mps * math.hypot(0.01, period / (4.0 * math.sqrt(3.0)))
    assert measurement.uncertainty_mps == pytest.approx(expected)


@pytest.mark.parametrize(
    ("sensor", "position", "needle"),
    [
        (2, 0.2, "sensor event from sensor 2, but 2 sensors are configured"),
        (1, 0.15, "sensor 1 reports position 0.15 m, configured 0.135 m"),
        (0, math.nan, "sensor 0 reports position nan m"),
    ],
)
def test_sensors_the_configuration_does_not_have_are_refused(
    steady_estimator: VehicleEstimator, sensor: int, position: float, needle: str
) -> None:
    outcome = MeasurementSource(SENSORS).on_sensor_edge(
        steady_estimator, 5.0, sensor, position, 1, True
    )
    assert isinstance(outcome, str)
    assert needle in outcome


def test_operator_speeds_are_checked_and_get_a_default_uncertainty(
    steady_estimator: VehicleEstimator,
) -> None:
    source = MeasurementSource(SENSORS)
    measurement = source.operator_speed(steady_estimator, 0.02, 0.0)
    assert isinstance(measurement, SpeedMeasurement)
    assert measurement.uncertainty_mps == pytest.approx(0.02 * 0.02)
    for speed, sigma, needle in (
        (math.nan, 0.0, "speed_mps=nan is not a finite number"),
        (math.inf, 0.0, "speed_mps=inf is not a finite number"),
        (0.02, math.inf, "uncertainty_mps=inf is not a finite number"),
        (0.02, -1e-3, "uncertainty_mps=-0.001 is negative"),
    ):
        refused = source.operator_speed(steady_estimator, speed, sigma)
        assert isinstance(refused, str)
        assert needle in refused
    settling = VehicleEstimator(EstimatorConfig(part=PartModel()))
    refused = source.operator_speed(settling, 0.02, 0.0)
    assert isinstance(refused, str)
    assert "the estimator is settling" in refused


def test_the_configuration_of_the_sensors_is_checked() -> None:
    with pytest.raises(ParameterError, match="transit sensor 3 does not exist"):
        MeasurementSource(SENSORS, (0, 3))
    with pytest.raises(ParameterError, match="must lie downstream"):
        MeasurementSource(SENSORS, (1, 0))
    assert MeasurementSource(()).timer is None  # no sensors: no transit calibration


def test_the_calibration_file_round_trips_and_refuses_what_it_cannot_use(tmp_path: Path) -> None:
    nominal = PartModel()
    belief = PartBelief.prior(nominal)
    path = tmp_path / "calibration.yaml"
    assert read_calibration(path, nominal) is None  # no file: nothing calibrated yet
    write_calibration(path, belief)
    back = read_calibration(path, nominal)
    assert back is not None
    np.testing.assert_allclose(back.mean, belief.mean)
    np.testing.assert_allclose(back.covariance, belief.covariance)
    document = yaml.safe_load(path.read_text())
    assert document["values"]["static_friction"] == pytest.approx(0.2)
    cases = {
        "not YAML": "format: [unterminated\n",
        "not a feeder_ros/part_calibration file": "format: something_else\n",
        "this build reads version 1": path.read_text().replace("version: 1", "version: 7"),
        "calibrated for another part": path.read_text().replace(
            "static_friction: 0.2\n", "static_friction: 0.3\n", 1
        ),
        "non-physical calibration": path.read_text().replace("- 0.0\n", "- 2.0\n", 2),
    }
    for needle, text in cases.items():
        bad = tmp_path / "bad.yaml"
        bad.write_text(text)
        with pytest.raises(CalibrationFileError, match=needle):
            read_calibration(bad, nominal)


def test_a_transit_ahead_of_the_accelerometer_stream_waits_for_it(
    steady_estimator: VehicleEstimator,
) -> None:
    """Sensor edges may arrive before the samples of the same moment (a loaded estimator drains
    late): the transit waits, is measured once the stream reaches its end, and is refused with the
    lag only when the stream falls more than MAX_STREAM_LAG_S behind the sensors."""
    reached = steady_estimator.last_estimate.t_s
    steady = steady_estimator.steady_since_s
    source = MeasurementSource(SENSORS)
    source.on_sensor_edge(steady_estimator, steady + 0.1, 0, 0.05, 1, True)
    assert source.on_sensor_edge(steady_estimator, reached + 2.0, 1, 0.135, 1, True) is None
    assert source.waiting == 1
    assert source.due(steady_estimator) == []  # the stream is still 2 s short of its end
    assert source.waiting == 1

    class Caught:  # the same estimator, its samples now past the transit's end
        def __init__(self, inner: VehicleEstimator, t_s: float) -> None:
            self._inner = inner
            self.last_estimate = dataclasses.replace(inner.last_estimate, t_s=t_s)

        def __getattr__(self, name: str) -> object:
            return getattr(self._inner, name)

    [measured] = source.due(Caught(steady_estimator, reached + 2.0))  # type: ignore[arg-type]
    assert isinstance(measured, SpeedMeasurement)
    assert measured.speed_mps == pytest.approx(0.085 / (reached + 1.9 - steady))
    assert source.waiting == 0

    # the stream stops: once the sensors are 10 s past the transit, it is refused with the lag
    source.on_sensor_edge(steady_estimator, reached + 1.0, 0, 0.05, 2, True)
    assert source.on_sensor_edge(steady_estimator, reached + 5.0, 1, 0.135, 2, True) is None
    source.on_sensor_edge(steady_estimator, reached + 14.0, 0, 0.05, 3, True)
    assert source.due(steady_estimator) == []
    source.on_sensor_edge(steady_estimator, reached + 15.5, 0, 0.05, 4, True)
    [refused] = source.due(steady_estimator)
    assert isinstance(refused, str)
    assert f"transit ending at {reached + 5.0:.3f} s not used" in refused
    assert f"has reached only {reached:.3f} s, more than 10 s behind the sensors" in refused
    assert source.waiting == 0
