"""Online calibration of the part model from the truth a cell already has (ROS-free).

A cell measures part speeds in length and time: transits between part-present sensors a known
distance apart (the paper's 8.5 cm timing), parts leaving the end of the track, an operator with a
stopwatch. Each such measurement, taken while the carrier ran at one steady operating point, is one
equation ``y = h(theta; carrier) + e``: the steady mean speed the part model predicts on that
operating point's carrier model (:func:`~feeder_ros.estimation.part_belief.predict_speed`) plus
the measurement's error. :class:`Calibrator` folds measurements one at a time into the Gaussian
belief over ``theta = (ln L, ln D, ln k)`` (:class:`~feeder_ros.estimation.part_belief.PartBelief`):
a Gauss-Newton iteration on the prior (the current belief) and the new equation, whose curvature at
the optimum is the new covariance (a Laplace, or iterated-EKF, update).

What the data identify (``docs/model.md``, section 8): one operating point gives one equation, a
curve in the (L, D) plane; the covariance keeps the other direction as uncertain as before.
Operating points with different slip patterns constrain different combinations, so two or more
fix L and D. A point where the part never slips has ``h`` independent of L and D: it carries no
friction information, and the update leaves the belief unchanged. ``k`` is told apart from
friction only weakly; it stays near its prior unless the points disagree with a pure friction
change.

Refused (the belief does not change, the reason names the value): a speed that is not finite, not
positive, or faster than the carrier itself can carry a part (its peak velocity); an uncertainty
that is not finite and positive; an update whose result would give ``mu_d > mu_s``, a friction
coefficient outside ``(0, 2]`` or a gain outside ``[0.5, 2]``; a measurement more than
``outlier_sigma`` standard deviations from the prediction (a wrong sensor spacing, a part that
jammed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from feeder_ros.estimation.carrier_velocity import HarmonicFit
from feeder_ros.estimation.part_belief import CarrierRun, PartBelief, predict_speed
from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = ["CalibrationResult", "Calibrator", "SpeedMeasurement"]

F64 = npt.NDArray[np.float64]
SOURCES = ("transit", "operator")
MAX_FRICTION = 2.0
GAIN_RANGE = (0.5, 2.0)


@dataclass(frozen=True)
class SpeedMeasurement:
    """A part speed measured in length and time while the carrier ran as ``fit`` describes.

    ``drive``: (frequency Hz, amplitude) of the operating point, for the record."""

    fit: HarmonicFit
    speed_mps: float
    uncertainty_mps: float
    source: str
    drive: tuple[float, float] = (math.nan, math.nan)


@dataclass(frozen=True)
class CalibrationResult:
    accepted: bool
    reason: str  #: why it was refused, or a summary of the update
    belief: PartBelief
    predicted_mps: float = math.nan  #: the prediction before the update
    predicted_uncertainty_mps: float = math.nan


@dataclass
class _Point:
    """The measurements at one operating point: their weighted mean and the latest carrier model."""

    run: CarrierRun  #: the latest carrier model of the point, sampled
    weight: float = 0.0  #: sum of 1/sigma^2
    weighted_sum: float = 0.0  #: sum of y/sigma^2
    count: int = 0

    @property
    def speed_mps(self) -> float:
        return self.weighted_sum / self.weight

    def uncertainty_mps(self, systematic: float) -> float:
        """Of the mean: the measurements' own spread averages down, the model's systematic error
        (``systematic`` relative) does not."""
        return math.hypot(1.0 / math.sqrt(self.weight), systematic * abs(self.speed_mps))


class Calibrator:
    """Estimates the part model from speed measurements (see the module docstring).

    Measurements are grouped by operating point (drive frequency and amplitude); each point is one
    equation, its measured speed the weighted mean of its measurements with their uncertainty
    (plus ``systematic`` relative: the part model's own error at the true values, which no number
    of transits averages away). The belief is the maximum a posteriori estimate over every point
    and the prior (``scipy.optimize.least_squares`` on the whitened residuals, started from the
    current estimate and from the prior mean), its covariance the inverse Gauss-Newton curvature
    there (a Laplace approximation). ``dt_s``: the sample interval the part model is run at.
    """

    def __init__(
        self,
        prior: PartBelief,
        dt_s: float = 1e-3,
        outlier_sigma: float = 5.0,
        systematic: float = 0.005,
        settle_periods: int = 6,
        periods: int = 12,
    ) -> None:
        if not (is_number(dt_s) and math.isfinite(dt_s) and 0.0 < dt_s <= 0.1):
            raise ParameterError(f"dt_s={dt_s!r} must be in (0, 0.1]")
        if not (is_number(outlier_sigma) and outlier_sigma > 0.0):
            raise ParameterError(f"outlier_sigma={outlier_sigma!r} must be > 0")
        if not (is_number(systematic) and 0.0 <= systematic < 1.0):
            raise ParameterError(f"systematic={systematic!r} must be in [0, 1)")
        self._prior = prior
        self._belief = prior
        self._dt = float(dt_s)
        self._outlier = float(outlier_sigma)
        self._systematic = float(systematic)
        self._runs = (int(settle_periods), int(periods))
        self._points: dict[tuple[float, float], _Point] = {}

    @property
    def belief(self) -> PartBelief:
        return self._belief

    @property
    def prior(self) -> PartBelief:
        return self._prior

    def reset(self) -> None:
        """Back to the prior: every measurement forgotten."""
        self._belief = self._prior
        self._points.clear()

    def restore(self, belief: PartBelief) -> None:
        """Continue from a stored belief (read back from a calibration file): it becomes the prior
        of the measurements that follow."""
        self._prior = belief
        self._belief = belief
        self._points.clear()

    def predict(self, fit: HarmonicFit) -> tuple[float, float]:
        """(speed, standard uncertainty) [m/s] the current belief predicts on ``fit``."""
        settle, periods = self._runs
        pred = predict_speed(fit, self._belief, self._dt, settle, periods)
        return pred.speed_mps, pred.uncertainty_mps

    def add(self, measurement: SpeedMeasurement) -> CalibrationResult:
        belief = self._belief
        problem = _check_measurement(measurement)
        if problem:
            return CalibrationResult(False, problem, belief)
        fit = measurement.fit
        peak = float(np.max(np.abs(fit.velocity(_one_period(fit, self._dt)))))
        if measurement.speed_mps > peak / belief.gain:
            return CalibrationResult(
                False,
                f"measured speed {measurement.speed_mps:.6g} m/s is faster than the carrier's "
                f"peak velocity {peak / belief.gain:.6g} m/s: no part can move that fast",
                belief,
            )
        predicted, sigma = self.predict(fit)
        spread = math.hypot(sigma, measurement.uncertainty_mps, self._systematic * predicted)
        off = abs(measurement.speed_mps - predicted) / spread
        if off > self._outlier:
            return CalibrationResult(
                False,
                f"measured speed {measurement.speed_mps:.6g} m/s is {off:.1f} sigma from the "
                f"predicted {predicted:.6g} +- {sigma:.2g} m/s (limit {self._outlier:g} sigma): "
                "not used",
                belief,
                predicted,
                sigma,
            )
        key = (round(measurement.drive[0], 6), round(measurement.drive[1], 6))
        if not all(math.isfinite(x) for x in key):
            key = (float(len(self._points)) + 0.5, math.inf)  # unnamed point: its own equation
        previous = self._points.get(key)
        run = CarrierRun.of(fit, self._dt, *self._runs)
        point = (
            _Point(run)
            if previous is None
            else _Point(run, previous.weight, previous.weighted_sum, previous.count)
        )
        w = 1.0 / measurement.uncertainty_mps**2
        point.weight += w
        point.weighted_sum += w * measurement.speed_mps
        point.count += 1
        self._points[key] = point
        mean, cov = self._solve()
        problem = _check_theta(mean, belief)
        if problem:
            if previous is None:
                del self._points[key]
            else:
                self._points[key] = previous
            return CalibrationResult(False, problem, belief, predicted, sigma)
        self._belief = belief.with_values(
            mean,
            cov,
            transits=belief.transits + (measurement.source == "transit"),
            operator_speeds=belief.operator_speeds + (measurement.source == "operator"),
            points=tuple(k for k in self._points if math.isfinite(k[1])),
        )
        updated = self._belief
        return CalibrationResult(
            True,
            f"{measurement.source} {measurement.speed_mps:.6g} m/s (predicted {predicted:.6g} +- "
            f"{sigma:.2g}): mu_s {updated.static_friction:.4g}, mu_d "
            f"{updated.kinetic_friction:.4g}, gain {updated.gain:.4g}",
            updated,
            predicted,
            sigma,
        )

    def _solve(self) -> tuple[F64, F64]:
        """The MAP estimate over the points and the prior, and its Laplace covariance."""
        prior = self._prior
        root = np.linalg.cholesky(np.linalg.inv(prior.covariance))  # info = R R^T
        points = list(self._points.values())
        ys = np.array([p.speed_mps for p in points])
        sig = np.array([p.uncertainty_mps(self._systematic) for p in points])

        def residuals(theta: F64) -> F64:
            k = math.exp(float(theta[2]))
            part = prior.measured_part(theta)
            h = [p.run.mean_speed(part) / k for p in points]
            return np.concatenate(((ys - np.array(h)) / sig, root.T @ (theta - prior.mean)))

        best = None
        for start in (self._belief.mean, prior.mean):
            result = least_squares(
                residuals, start, diff_step=np.full(3, 0.01), x_scale=prior.std, max_nfev=60
            )
            if best is None or result.cost < best.cost:
                best = result
        assert best is not None
        J = np.asarray(best.jac, np.float64)
        cov = np.linalg.inv(J.T @ J)
        return np.asarray(best.x, np.float64), np.asarray(0.5 * (cov + cov.T), np.float64)


def _one_period(fit: HarmonicFit, dt_s: float) -> F64:
    period = 1.0 / fit.base_frequency_hz
    n = max(8, round(period / min(dt_s, period / 64)))
    return np.asarray(fit.t_end_s - period + period * np.arange(n) / n, np.float64)


def _check_measurement(m: SpeedMeasurement) -> str:
    if m.source not in SOURCES:
        return f"source={m.source!r} is not one of {SOURCES}"
    y, s = m.speed_mps, m.uncertainty_mps
    if not (is_number(y) and math.isfinite(y)):
        return f"measured speed {y!r} is not a finite number"
    if y <= 0.0:
        return f"measured speed {y!r} m/s is not positive (a transit times a forward motion)"
    if not (is_number(s) and math.isfinite(s) and s > 0.0):
        return f"speed uncertainty {s!r} m/s must be finite and > 0"
    return ""


def _check_theta(theta: F64, belief: PartBelief) -> str:
    if not np.all(np.isfinite(theta)):
        return f"the fit diverged (theta={theta.tolist()})"
    ln_l, ln_d, ln_k = (float(x) for x in theta)
    g_kappa = belief.nominal.gravity_mps2 * belief.nominal.friction_multiplier
    if ln_d > ln_l:
        return (
            f"the fit would give mu_d > mu_s (slip deceleration {math.exp(ln_d):.4g} > stick "
            f"limit {math.exp(ln_l):.4g} m/s^2): not used"
        )
    gain = math.exp(ln_k)
    if not GAIN_RANGE[0] <= gain <= GAIN_RANGE[1]:
        return f"the fit would give an accelerometer gain of {gain:.4g}, outside {GAIN_RANGE}"
    mu_s = math.exp(ln_l) / g_kappa
    if mu_s > MAX_FRICTION:
        return f"the fit would give mu_s = {mu_s:.4g} > {MAX_FRICTION:g}: non-physical"
    return ""
