"""Online calibration of the part model from the truth a cell already has (ROS-free).

A cell measures part speeds in length and time: transits between part-present sensors a known
distance apart (the paper's 8.5 cm timing), parts leaving the end of the track, an operator with a
stopwatch. Each such measurement, taken while the carrier ran at one steady operating point, is one
equation ``y = h(theta; carrier) + e``: the steady mean speed a part with ``theta`` reaches on that
operating point's carrier model (``CarrierRun``) plus the measurement's error. :class:`Calibrator`
holds the posterior over ``theta = (ln L, ln D, ln k)`` as weighted samples (importance sampling
from the prior, redrawn around the posterior as it narrows; see the class) and hands the
estimator a :class:`~feeder_ros.estimation.part_belief.PartBelief`. Samples, not a linearisation:
``h`` jumps where a carrier peak grazes the stick limit, and a Gauss-Newton fit sat on such an
edge with a covariance far too small (tried; ``docs/model.md`` section 12.4).

What the data identify: one operating point gives one equation, a curve in the (L, D) plane; the
posterior stays as wide as before along it, and other operating points keep much of their
uncertainty. Operating points with different slip patterns constrain different combinations, so
two or more fix L and D. A point where the part never slips has ``h = 0`` for every plausible
part: it carries no friction information (a speed measured there is an outlier). ``k`` is told
apart from friction only weakly; it stays near its prior unless the points disagree with a pure
friction change.

Refused (the belief does not change, the reason names the value): a speed that is not finite, not
positive, or faster than the carrier itself can carry a part (its peak velocity); an uncertainty
that is not finite and positive; a measurement more than ``outlier_sigma`` standard deviations
from the prediction (a wrong sensor spacing, a part that jammed); an update after which most of
the posterior wants ``mu_d >= mu_s``, or whose mean has a friction coefficient above 2 or a gain
outside ``[0.5, 2]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from feeder_ros.estimation.carrier_velocity import HarmonicFit
from feeder_ros.estimation.part_belief import (
    CarrierRun,
    PartBelief,
    gaussian_particles,
)
from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = ["CalibrationResult", "Calibrator", "SpeedMeasurement"]

F64 = npt.NDArray[np.float64]
SOURCES = ("transit", "operator")
MAX_FRICTION = 2.0
#: operating points whose measurements the calibration keeps: the most recently measured ones. Each
#: kept point costs a run per particle at every rejuvenation, and a drive whose speed trim moves
#: the amplitude makes a new point at every step: unbounded, a 30-minute soak took the estimator
#: from 21 % to 86 % of a core. An older point's information leaves the posterior (a window)
MAX_POINTS = 12
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
    """The measurements at one operating point: their weighted mean, the latest carrier model
    (sampled) and every particle's predicted speed on it."""

    run: CarrierRun
    speeds: F64  #: per particle [true m/s]
    weight: float = 0.0  #: sum of 1/sigma^2
    weighted_sum: float = 0.0  #: sum of y/sigma^2
    count: int = 0

    @property
    def speed_mps(self) -> float:
        return self.weighted_sum / self.weight

    def log_likelihood(self, systematic: float) -> F64:
        """Of each particle: the measurements' own spread averages down, the part model's
        systematic error (``systematic`` relative) does not."""
        sigma2 = 1.0 / self.weight + (systematic * self.speed_mps) ** 2
        return np.asarray(-0.5 * (self.speed_mps - self.speeds) ** 2 / sigma2, np.float64)


class Calibrator:
    """Estimates the part model from speed measurements (see the module docstring).

    The posterior is carried by ``particles`` samples of ``theta`` with importance weights: drawn
    from the prior (scrambled Sobol, deterministic), weighted by the likelihood of every operating
    point, and rejuvenated (resampled, then moved by Metropolis steps on the posterior) whenever
    the weights concentrate on fewer than half of them. Measurements are grouped by operating
    point (drive frequency and amplitude); each point is one equation, its measured speed the
    weighted mean of its measurements (uncertainty: theirs averaged down, plus ``systematic``
    relative, the part model's own error at the true values). Each particle is run once per point
    (``settle_periods`` + ``periods`` response periods at ``dt_s``), so a transit at a known point
    costs only a re-weighting; a new point or a redraw runs every particle.
    """

    def __init__(
        self,
        prior: PartBelief,
        dt_s: float = 1e-3,
        outlier_sigma: float = 5.0,
        systematic: float = 0.005,
        particles: int = 256,
        settle_periods: int = 6,
        periods: int = 12,
    ) -> None:
        if not (is_number(dt_s) and math.isfinite(dt_s) and 0.0 < dt_s <= 0.1):
            raise ParameterError(f"dt_s={dt_s!r} must be in (0, 0.1]")
        if not (is_number(outlier_sigma) and outlier_sigma > 0.0):
            raise ParameterError(f"outlier_sigma={outlier_sigma!r} must be > 0")
        if not (is_number(systematic) and 0.0 <= systematic < 1.0):
            raise ParameterError(f"systematic={systematic!r} must be in [0, 1)")
        if not (isinstance(particles, int) and particles >= 16 and not particles & (particles - 1)):
            raise ParameterError(f"particles={particles!r} must be a power of two >= 16")
        self._dt = float(dt_s)
        self._outlier = float(outlier_sigma)
        self._systematic = float(systematic)
        self._count = particles
        self._runs = (int(settle_periods), int(periods))
        self.restore(prior)

    @property
    def belief(self) -> PartBelief:
        return self._belief

    @property
    def prior(self) -> PartBelief:
        return self._prior

    def reset(self) -> None:
        """Back to the prior: every measurement forgotten."""
        self.restore(self._prior)

    def restore(self, belief: PartBelief) -> None:
        """Start from ``belief`` (the prior, or one read back from a calibration file): it becomes
        the prior of the measurements that follow."""
        self._prior = belief
        self._belief = belief
        self._points: dict[tuple[float, float], _Point] = {}
        self._prior_info = _information(belief.covariance)
        self._draw(belief.mean, belief.covariance, seed=0)

    def _draw(self, mean: F64, cov: F64, seed: int) -> None:
        """New particles from N(mean, cov); their proposal and prior log densities."""
        theta = gaussian_particles(mean, cov, self._count, seed)
        self._theta = theta
        self._log_q = _log_normal(theta, mean, _information(cov))
        self._log_p = _log_normal(theta, self._prior.mean, self._prior_info)
        for point in self._points.values():
            point.speeds = point.run.speeds(self._prior, theta)

    def _weights(self) -> F64:
        log_w = self._log_p - self._log_q
        for point in self._points.values():
            log_w = log_w + point.log_likelihood(self._systematic)
        w = np.exp(log_w - np.max(log_w))
        return np.asarray(w / np.sum(w), np.float64)

    def _predictive(self, speeds: F64, weights: F64) -> tuple[float, float]:
        mean = float(np.dot(weights, speeds))
        return mean, math.sqrt(max(float(np.dot(weights, (speeds - mean) ** 2)), 0.0))

    def predict(self, fit: HarmonicFit) -> tuple[float, float]:
        """(speed, standard uncertainty) [m/s] the current posterior predicts on ``fit``."""
        run = CarrierRun.of(fit, self._dt, *self._runs)
        return self._predictive(run.speeds(self._prior, self._theta), self._weights())

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
        key = (round(measurement.drive[0], 6), round(measurement.drive[1], 6))
        if not all(math.isfinite(x) for x in key):
            key = (float(len(self._points)) + 0.5, math.inf)  # unnamed point: its own equation
        previous = self._points.get(key)
        run = CarrierRun.of(fit, self._dt, *self._runs)
        speeds = run.speeds(self._prior, self._theta)
        predicted, sigma = self._predictive(speeds, self._weights())
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
        saved = (self._theta, self._log_q, self._log_p, dict(self._points))
        saved_speeds = {k: p.speeds for k, p in self._points.items()}
        point = _Point(run, speeds)
        if previous is not None:
            point.weight, point.weighted_sum = previous.weight, previous.weighted_sum
            point.count = previous.count
        w = 1.0 / measurement.uncertainty_mps**2
        point.weight += w
        point.weighted_sum += w * measurement.speed_mps
        point.count += 1
        self._points.pop(key, None)  # (re)inserted last: the dict's order is the measuring order
        self._points[key] = point
        while len(self._points) > MAX_POINTS:
            del self._points[next(iter(self._points))]  # the least recently measured point
        weights = self._refined_weights()
        problem = _check_posterior(self._theta, weights, belief)
        if problem:
            self._theta, self._log_q, self._log_p, self._points = saved
            for k, p in self._points.items():
                p.speeds = saved_speeds[k]
            return CalibrationResult(False, problem, belief, predicted, sigma)
        self._belief = belief.updated(
            (self._theta, weights),
            self._estimate(weights),
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

    def _refined_weights(self) -> F64:
        """The posterior weights; when fewer than half of the particles carry them, the set is
        rejuvenated first (resample-move: see :meth:`_rejuvenate`) and the weights are equal."""
        weights = self._weights()
        if 1.0 / float(np.sum(weights**2)) >= self._count / 2.0:
            return weights
        self._rejuvenate(weights)
        return self._weights()

    def _rejuvenate(self, weights: F64, moves: int = 6) -> None:
        """Resample the particles by their weights, then move each by a few Metropolis steps that
        leave the posterior invariant (a random walk scaled to the posterior's own spread,
        floored at 0.2 %): duplicates spread out again, along a curved posterior too, and the set
        stays a sample of the posterior however narrow it gets."""
        count = self._count
        positions = (np.arange(count) + 0.5) / count
        index = np.minimum(np.searchsorted(np.cumsum(weights), positions), count - 1)
        theta = self._theta[index].copy()
        mean = weights @ self._theta
        centred = self._theta - mean
        cov = (centred * weights[:, None]).T @ centred + np.diag(np.full(3, 0.002**2))
        step = np.linalg.cholesky(0.5 * (cov + cov.T)) * (2.38 / math.sqrt(3.0))
        points = list(self._points.values())
        speeds = [p.speeds[index].copy() for p in points]
        log_target = self._log_posterior(theta, speeds)
        rng = np.random.default_rng(len(points) * 7919 + sum(p.count for p in points))
        for _ in range(moves):
            proposal = theta + rng.standard_normal((count, 3)) @ step.T
            inside = proposal[:, 1] < proposal[:, 0] - 1e-3  # mu_d < mu_s
            proposal[~inside] = theta[~inside]
            new_speeds = [p.run.speeds(self._prior, proposal) for p in points]
            new_target = self._log_posterior(proposal, new_speeds)
            accept = inside & (np.log(rng.random(count)) < new_target - log_target)
            theta[accept] = proposal[accept]
            log_target[accept] = new_target[accept]
            for old, new in zip(speeds, new_speeds, strict=True):
                old[accept] = new[accept]
        self._theta = theta
        self._log_p = _log_normal(theta, self._prior.mean, self._prior_info)
        # drawn from the posterior: their density is the posterior's (up to a constant), so the
        # weights of later measurements are their likelihood alone
        self._log_q = log_target
        for point, values in zip(points, speeds, strict=True):
            point.speeds = values

    def _estimate(self, weights: F64) -> F64:
        """The posterior mean if it fits the measurements about as well as the best particle (a
        parameter the data leave free then stays at its mean, not at a random particle's value),
        else the best particle: the one of highest posterior density. (Not the largest weight:
        after a rejuvenation the particles are drawn from the posterior and weigh the same, so
        the largest weight picked one at random, and the estimate with it; a calibrated point of
        the mismatch benchmark was 9.7 % off that way.)"""
        points = list(self._points.values())
        mean = weights @ self._theta
        density = self._log_posterior(self._theta, [p.speeds for p in points])
        best = self._theta[int(np.argmax(density))]
        candidates = np.vstack((mean, best))
        speeds = [p.run.speeds(self._prior, candidates) for p in points]
        log = self._log_posterior(candidates, speeds)
        return np.asarray(mean if log[0] >= log[1] - 2.0 else best, np.float64)

    def _log_posterior(self, theta: F64, speeds: list[F64]) -> F64:
        log = _log_normal(theta, self._prior.mean, self._prior_info)
        for point, values in zip(self._points.values(), speeds, strict=True):
            sigma2 = 1.0 / point.weight + (self._systematic * point.speed_mps) ** 2
            log = log - 0.5 * (point.speed_mps - values) ** 2 / sigma2
        return np.asarray(log, np.float64)


def _information(cov: F64) -> F64:
    """The (pseudo-)inverse of a covariance: a parameter known exactly has no density term."""
    return np.asarray(np.linalg.pinv(cov, hermitian=True), np.float64)


def _log_normal(theta: F64, mean: F64, info: F64) -> F64:
    d = theta - mean
    return np.asarray(-0.5 * np.einsum("ij,jk,ik->i", d, info, d), np.float64)


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


def _check_posterior(theta: F64, weights: F64, belief: PartBelief) -> str:
    mean = weights @ theta
    if not np.all(np.isfinite(mean)):
        return f"the calibration diverged (theta={mean.tolist()})"
    ln_l, ln_d, ln_k = (float(x) for x in mean)
    at_cap = float(np.sum(weights[theta[:, 1] >= theta[:, 0] - 0.02]))
    if at_cap > 0.5:  # the part model caps D below L: most of the weight pushing at the cap
        return (
            f"the fit would give mu_d >= mu_s ({100 * at_cap:.0f} % of the posterior at the "
            f"limit; slip deceleration {math.exp(ln_d):.4g}, stick limit {math.exp(ln_l):.4g} "
            "m/s^2): not used"
        )
    gain = math.exp(ln_k)
    if not GAIN_RANGE[0] <= gain <= GAIN_RANGE[1]:
        return f"the fit would give an accelerometer gain of {gain:.4g}, outside {GAIN_RANGE}"
    g_kappa = belief.nominal.gravity_mps2 * belief.nominal.friction_multiplier
    mu_s = math.exp(ln_l) / g_kappa
    if mu_s > MAX_FRICTION:
        return f"the fit would give mu_s = {mu_s:.4g} > {MAX_FRICTION:g}: non-physical"
    return ""
