"""The part model's uncertainty and its calibration from measured speeds (pure core, no ROS).

The plant here is not the model: its friction is 20 % and 10 % off the nominal values and its
accelerometer reads 2 % high. The carrier models are fitted to the plant's noisy accelerometer as
the estimator does; the "measured" speeds are the exact simulator's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from feeder_ros.estimation import EstimatorConfig, HarmonicFit, PartModel, VehicleEstimator
from feeder_ros.estimation.calibration import MAX_POINTS, Calibrator, SpeedMeasurement
from feeder_ros.estimation.carrier_velocity import select_period_order
from feeder_ros.estimation.part_belief import CarrierRun, PartBelief, predict_speed
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.simulation import simulate

RATE = 1000.0
NOISE_SIGMA = 0.0015 * math.sqrt(RATE / 2.0)  # 1.5 mm/s^2/sqrt(Hz): the simulator's default
PLANT_FRICTION = (0.24, 0.09)  # nominal: 0.2, 0.1
PLANT_GAIN = 1.02
POINTS = ((22.0, 20.0), (26.0, 40.0), (33.0, 20.0), (31.0, 40.0))
NOMINAL = PartModel()


@dataclass(frozen=True)
class Point:
    drive: tuple[float, float]
    fit: HarmonicFit
    true_mps: float


def _plant_point(frequency: float, amplitude: float, seed: int) -> Point:
    params = FeederParameters(
        damping_ns_per_m=200.0,
        drive_frequency_hz=frequency,
        drive_amplitude_n=amplitude,
        track_length_m=1e3,
        static_friction=PLANT_FRICTION[0],
        kinetic_friction=PLANT_FRICTION[1],
    )
    sim = simulate(params, 8.0, RATE)
    t = sim.t_s
    rng = np.random.default_rng(seed)
    measured = PLANT_GAIN * sim.carrier_a_mps2 + rng.normal(0.0, NOISE_SIGMA, t.size) + 0.03
    x = sim.part_x_m[:, 0]
    k0 = int(np.searchsorted(t, 5.0))
    true = float((x[-1] - x[k0]) / (t[-1] - t[k0]))
    steady = t >= 7.0
    _, fit = select_period_order(t[steady], measured[steady], frequency, 6, 450.0)
    return Point((frequency, amplitude), fit.significant(3.0), true)


@pytest.fixture(scope="module")
def points() -> list[Point]:
    return [_plant_point(f, a, seed) for seed, (f, a) in enumerate(POINTS)]


def test_the_prior_is_the_nominal_part_with_its_stated_uncertainty() -> None:
    belief = PartBelief.prior(NOMINAL, friction_uncertainty=0.3, gain_uncertainty=0.03)
    assert belief.static_friction == pytest.approx(0.2)
    assert belief.kinetic_friction == pytest.approx(0.1)
    assert belief.gain == 1.0
    assert belief.std == pytest.approx([0.3, 0.3, 0.03])
    # the estimator runs the part on the measured carrier: limits scaled by the gain
    scaled = belief.measured_part(np.array([*belief.mean[:2], math.log(1.1)]))
    assert scaled.stick_limit_mps2 == pytest.approx(1.1 * NOMINAL.stick_limit_mps2)
    assert scaled.slip_deceleration_mps2 == pytest.approx(1.1 * NOMINAL.slip_deceleration_mps2)
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ParameterError, match="friction_uncertainty"):
            PartBelief.prior(NOMINAL, friction_uncertainty=bad)


def test_uncalibrated_predictions_cover_the_mismatched_plant(points: list[Point]) -> None:
    prior = PartBelief.prior(NOMINAL)
    for point in points:
        prediction = predict_speed(point.fit, prior)
        error = prediction.speed_mps - point.true_mps
        assert abs(error) > 0.02 * point.true_mps or point.drive == (31.0, 40.0)  # mismatched
        assert abs(error) < 2.0 * prediction.uncertainty_mps, (point.drive, error, prediction)
        # an exactly known part model has no uncertainty of its own
        known = PartBelief(NOMINAL, prior.mean, np.zeros((3, 3)))
        assert predict_speed(point.fit, known).uncertainty_mps == 0.0


def test_transits_at_several_points_find_the_plant(points: list[Point]) -> None:
    calibrator = Calibrator(PartBelief.prior(NOMINAL))
    rng = np.random.default_rng(7)
    for _ in range(5):
        for point in points:
            measured = point.true_mps * (1.0 + rng.normal(0.0, 0.01))
            result = calibrator.add(
                SpeedMeasurement(point.fit, measured, 0.01 * measured, "transit", point.drive)
            )
            assert result.accepted, result.reason
    belief = calibrator.belief
    assert belief.transits == 5 * len(points)
    assert set(belief.points) == set(POINTS)
    assert belief.static_friction == pytest.approx(PLANT_FRICTION[0], rel=0.03)
    assert belief.kinetic_friction == pytest.approx(PLANT_FRICTION[1], rel=0.05)
    assert belief.gain == pytest.approx(PLANT_GAIN, abs=0.015)
    for point in points:
        prediction = predict_speed(point.fit, belief)
        assert prediction.speed_mps == pytest.approx(point.true_mps, rel=0.02)
        assert prediction.uncertainty_mps < 0.02 * point.true_mps
        assert abs(prediction.speed_mps - point.true_mps) < 3.0 * math.hypot(
            prediction.uncertainty_mps, 0.005 * point.true_mps
        )


def test_one_point_fixes_its_own_speed_and_leaves_the_others_uncertain(
    points: list[Point],
) -> None:
    calibrator = Calibrator(PartBelief.prior(NOMINAL))
    here, elsewhere = points[0], points[2]
    before = predict_speed(elsewhere.fit, calibrator.belief).uncertainty_mps
    for _ in range(10):
        calibrator.add(
            SpeedMeasurement(here.fit, here.true_mps, 0.01 * here.true_mps, "transit", here.drive)
        )
    at_point = predict_speed(here.fit, calibrator.belief)
    assert at_point.speed_mps == pytest.approx(here.true_mps, rel=0.01)
    assert at_point.uncertainty_mps < 0.02 * here.true_mps
    # one equation in (L, D, k): a curve; another point keeps much of its uncertainty
    other = predict_speed(elsewhere.fit, calibrator.belief)
    assert other.uncertainty_mps > 5.0 * at_point.uncertainty_mps
    assert other.uncertainty_mps > 0.1 * before
    assert abs(other.speed_mps - elsewhere.true_mps) < 3.0 * other.uncertainty_mps


def test_a_point_without_slip_carries_no_friction_information() -> None:
    point = _plant_point(29.6, 0.4, 11)  # the paper's small force: the part follows the carrier
    prior = PartBelief.prior(NOMINAL)
    prediction = predict_speed(point.fit, prior)
    assert abs(prediction.speed_mps) < 1e-6
    assert prediction.uncertainty_mps < 1e-6  # no particle makes the part move: nothing to learn
    calibrator = Calibrator(prior)
    result = calibrator.add(SpeedMeasurement(point.fit, 1e-3, 1e-4, "transit", point.drive))
    assert not result.accepted  # 1 mm/s where no plausible part moves at all: an outlier
    assert calibrator.belief is prior


@pytest.mark.parametrize(
    ("speed", "sigma", "needle"),
    [
        (math.nan, 1e-4, "measured speed nan is not a finite number"),
        (math.inf, 1e-4, "measured speed inf is not a finite number"),
        (-0.01, 1e-4, "measured speed -0.01 m/s is not positive"),
        (0.0, 1e-4, "measured speed 0.0 m/s is not positive"),
        (0.01, math.nan, "speed uncertainty nan m/s must be finite and > 0"),
        (0.01, 0.0, "speed uncertainty 0.0 m/s must be finite and > 0"),
        (5.0, 1e-3, "is faster than the carrier's peak velocity"),
    ],
)
def test_impossible_measurements_are_refused_and_change_nothing(
    points: list[Point], speed: float, sigma: float, needle: str
) -> None:
    calibrator = Calibrator(PartBelief.prior(NOMINAL))
    before = calibrator.belief
    result = calibrator.add(SpeedMeasurement(points[0].fit, speed, sigma, "transit"))
    assert not result.accepted
    assert needle in result.reason
    assert calibrator.belief is before


def _calibrated(point: Point, transits: int) -> Calibrator:
    """The nominal prior calibrated by exact transits (0.1 mm/s uncertainty) at one point."""
    calibrator = Calibrator(PartBelief.prior(NOMINAL))
    for _ in range(transits):
        calibrator.add(SpeedMeasurement(point.fit, point.true_mps, 1e-4, "transit", point.drive))
    return calibrator


def test_a_measurement_far_from_any_plausible_part_is_an_outlier(points: list[Point]) -> None:
    point = points[0]
    calibrator = _calibrated(point, 5)
    settled = calibrator.belief
    # a jammed part, or a wrong sensor spacing: a third of the speed
    result = calibrator.add(
        SpeedMeasurement(point.fit, point.true_mps / 3.0, 1e-4, "transit", point.drive)
    )
    assert not result.accepted
    assert "sigma from the predicted" in result.reason
    assert calibrator.belief is settled


def test_a_fit_that_would_need_mu_d_above_mu_s_is_refused(points: list[Point]) -> None:
    """Speeds that only a part with as much sliding as static friction could give: refused."""
    prior = PartBelief(NOMINAL, PartBelief.prior(NOMINAL).mean, np.diag([1e-4, 1.0, 1e-6]))
    calibrator = Calibrator(prior, outlier_sigma=1e6)
    point = points[0]
    capped = np.array([[prior.mean[0], prior.mean[0], 0.0]])  # D at L: the slowest the cap allows
    slow = float(CarrierRun.of(point.fit, 1e-3, 6, 12).speeds(prior, capped)[0])
    result = calibrator.add(SpeedMeasurement(point.fit, slow, 1e-6, "transit", point.drive))
    assert not result.accepted
    assert "mu_d >= mu_s" in result.reason
    assert calibrator.belief is prior


def test_the_estimator_with_a_calibrated_belief_reports_the_plant(points: list[Point]) -> None:
    """The estimator's mean speed and its uncertainty follow the belief it is given."""
    point = points[1]
    params = FeederParameters(
        damping_ns_per_m=200.0,
        drive_frequency_hz=point.drive[0],
        drive_amplitude_n=point.drive[1],
        track_length_m=1e3,
        static_friction=PLANT_FRICTION[0],
        kinetic_friction=PLANT_FRICTION[1],
    )
    sim = simulate(params, 8.0, RATE)
    measured = PLANT_GAIN * sim.carrier_a_mps2 + np.random.default_rng(3).normal(
        0.0, NOISE_SIGMA, sim.t_s.size
    )
    x = sim.part_x_m[:, 0]
    calibrator = Calibrator(PartBelief.prior(NOMINAL))
    for other in points:
        for _ in range(3):
            calibrator.add(
                SpeedMeasurement(other.fit, other.true_mps, 0.01 * other.true_mps, "transit",
                                 other.drive)
            )  # fmt: skip
    records = {}
    for name, belief in (("prior", None), ("calibrated", calibrator.belief)):
        estimator = VehicleEstimator(EstimatorConfig(part=NOMINAL), belief)
        estimator.set_drive(*point.drive, 0.0)
        for k in range(0, sim.t_s.size, 50):
            record = estimator.push(sim.t_s[k : k + 50], measured[k : k + 50])
        k0 = int(np.searchsorted(sim.t_s, record.t_s - record.window_s))
        true = float((x[-1] - x[k0]) / (sim.t_s[-1] - sim.t_s[k0]))
        records[name] = (record, true)
    prior_record, true = records["prior"]
    assert abs(prior_record.mean_speed_mps - true) < 2.0 * prior_record.mean_speed_uncertainty_mps
    calibrated, true = records["calibrated"]
    assert calibrated.mean_speed_mps == pytest.approx(true, rel=0.02)
    assert calibrated.mean_speed_uncertainty_mps < 0.3 * prior_record.mean_speed_uncertainty_mps
    assert calibrated.mean_speed_confidence > prior_record.mean_speed_confidence
    # the carrier's velocity is reported in true units: the gain is divided out
    assert abs(calibrated.carrier_velocity_mps) < abs(prior_record.carrier_velocity_mps)


def test_a_restored_belief_is_the_prior_of_what_follows(points: list[Point]) -> None:
    point = points[0]
    stored = _calibrated(point, 3).belief
    fresh = Calibrator(PartBelief.prior(NOMINAL))
    fresh.restore(stored)
    assert fresh.belief is stored
    assert fresh.prior is stored
    fresh.reset()
    assert fresh.belief is stored  # reset returns to the (restored) prior
    run = CarrierRun.of(point.fit, 1e-3, 10, 20)
    assert predict_speed(run, stored).speed_mps == pytest.approx(point.true_mps, rel=0.01)


def test_only_the_most_recently_measured_points_are_kept(points: list[Point]) -> None:
    """A speed trim makes a new operating point at every step: the calibration keeps the
    MAX_POINTS measured last (its cost stays bounded), the belief lists exactly those."""
    calibrator = Calibrator(PartBelief.prior(NOMINAL))
    point = points[1]
    drives = [(point.drive[0], point.drive[1] * (1.0 + 0.001 * k)) for k in range(MAX_POINTS + 3)]
    for drive in drives:
        result = calibrator.add(SpeedMeasurement(point.fit, point.true_mps, 1e-4, "transit", drive))
        assert result.accepted, result.reason
    # measured again: the first point becomes the most recent and stays
    again = calibrator.add(SpeedMeasurement(point.fit, point.true_mps, 1e-4, "transit", drives[5]))
    assert again.accepted, again.reason
    order = [*drives[3:5], *drives[6:], drives[5]]  # 0-2 evicted; 5 measured last
    assert list(calibrator.belief.points) == [(round(f, 6), round(a, 6)) for f, a in order]
    assert calibrator.belief.transits == MAX_POINTS + 4
