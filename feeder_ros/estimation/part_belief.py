"""What the estimator believes about the part model, and how sure it is (ROS-free).

With one-way coupling a part's motion on a given carrier depends on friction only through the stick
limit ``L = mu_s*g*kappa`` and the slip deceleration ``D = mu_d*g*kappa`` (``docs/model.md``,
section 12.2): ``mu_s``, ``mu_d``, ``kappa`` and ``g`` are not separately identifiable, only
``L`` and ``D``. An accelerometer gain ``k`` (measured = ``k`` * true) is exactly equivalent to a
plant with ``L``, ``D`` and every velocity scaled by ``k``; only truth measured in length and time
separates it from friction. The belief is a distribution over

    theta = (ln L, ln D, ln k)       (L, D in true m/s^2; k dimensionless)

held as a set of equally weighted *particles* (samples), with their mean and covariance as its
summary: before any calibration, samples of a normal distribution around the nominal values with
the stated relative uncertainties (friction known to +-30 %, the gain to +-3 %); afterwards the
posterior of :mod:`~feeder_ros.estimation.calibration`. Samples, not a covariance, carry it
because the part's speed is not a smooth function of friction: where a carrier's acceleration
peak grazes the stick limit, 0.5 % more friction can cost 10 % of the speed (a slip per period
fewer), so a linearised propagation is confidently wrong exactly there.

The estimator runs the part on the *measured* carrier with ``L*k`` and ``D*k`` at the mean and
divides its speeds by ``k``; :func:`predict_speed` runs every particle on a carrier model and
reports the spread of their speeds around that estimate as its standard uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy.stats import norm, qmc

from feeder_ros.estimation.carrier_velocity import HarmonicFit
from feeder_ros.estimation.stick_slip_observer import PartModel, StickSlipObserver
from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = [
    "CarrierRun",
    "PartBelief",
    "SpeedPrediction",
    "gaussian_particles",
    "predict_speed",
]

F64 = npt.NDArray[np.float64]
#: particles a belief carries for the estimator's own uncertainty runs
BELIEF_PARTICLES = 64
#: the gap kept between ln D and ln L: a particle at or past it would have mu_d >= mu_s
MIN_LOG_MARGIN = 1e-3


def _check_fraction(name: str, value: float, upper: float) -> float:
    if not (is_number(value) and math.isfinite(value) and 0.0 <= value <= upper):
        raise ParameterError(f"{name}={value!r} must be finite and in [0, {upper:g}]")
    return float(value)


def gaussian_particles(mean: F64, covariance: F64, count: int, seed: int = 0) -> F64:
    """``count`` samples of N(mean, covariance) from a scrambled Sobol sequence (deterministic for
    a seed; ``count`` a power of two keeps its balance), each with ``ln D < ln L``: a sample past
    that is mirrored back into the region."""
    if count < 1 or count & (count - 1):
        raise ParameterError(f"count={count!r} must be a power of two")
    sobol = qmc.Sobol(3, scramble=True, seed=seed).random(count)
    z = norm.ppf(np.clip(sobol, 1e-9, 1.0 - 1e-9))
    values, vectors = np.linalg.eigh(0.5 * (covariance + covariance.T))
    root = vectors * np.sqrt(np.maximum(values, 0.0))
    theta = np.asarray(mean, np.float64) + z @ root.T
    over = theta[:, 1] - theta[:, 0] + MIN_LOG_MARGIN
    theta[:, 1] -= np.where(over > 0.0, 2.0 * over, 0.0)
    return np.asarray(theta, np.float64)


@dataclass(frozen=True)
class PartBelief:
    """A belief over ``theta = (ln L, ln D, ln k)`` (see the module docstring): equally weighted
    ``particles`` (n x 3) and their ``mean`` and ``covariance``.

    ``nominal`` carries ``kappa`` and ``g`` (to express ``L``, ``D`` as friction coefficients) and
    the nominal friction the prior is centred on; the values (``stick_limit_mps2``, ``gain``,
    ``static_friction``, ...) are those of ``estimate``, their uncertainties ``std``.
    ``transits``/``operator_speeds``: how many measurements went into it; ``points``: the (drive
    frequency, amplitude) they were taken at.
    """

    nominal: PartModel
    mean: F64
    covariance: F64
    particles: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    #: the theta the estimator runs: the posterior mean where its speeds agree with the
    #: measurements as well as the best particle's (within 2 in log-likelihood), else the best
    #: particle (the mean of a curved or split posterior need not fit the data); the prior's mean
    estimate: F64 = field(default_factory=lambda: np.full(3, np.nan))
    transits: int = 0
    operator_speeds: int = 0
    points: tuple[tuple[float, float], ...] = field(default=())

    def __post_init__(self) -> None:
        mean = np.array(self.mean, dtype=np.float64).reshape(3)
        cov = np.array(self.covariance, dtype=np.float64).reshape(3, 3)
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise ParameterError(f"belief mean {mean} / covariance {cov.tolist()} not finite")
        cov = 0.5 * (cov + cov.T)
        if np.any(np.linalg.eigvalsh(cov) < -1e-12):
            raise ParameterError(f"belief covariance {cov.tolist()} is not positive semi-definite")
        particles = np.array(self.particles, dtype=np.float64).reshape(-1, 3)
        if particles.shape[0] == 0:
            particles = gaussian_particles(mean, cov, BELIEF_PARTICLES)
        estimate = np.array(self.estimate, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(estimate)):
            estimate = mean.copy()
        object.__setattr__(self, "estimate", estimate)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "particles", particles)

    @classmethod
    def prior(
        cls, nominal: PartModel, friction_uncertainty: float = 0.3, gain_uncertainty: float = 0.03
    ) -> PartBelief:
        """The nominal part with relative standard uncertainties of its friction (``L`` and ``D``,
        independent) and of the accelerometer gain."""
        sf = _check_fraction("friction_uncertainty", friction_uncertainty, 2.0)
        sk = _check_fraction("gain_uncertainty", gain_uncertainty, 0.5)
        mean = np.array(
            [math.log(nominal.stick_limit_mps2), math.log(nominal.slip_deceleration_mps2), 0.0]
        )
        return cls(nominal, mean, np.diag([sf**2, sf**2, sk**2]))

    # -- values ------------------------------------------------------------------------------
    @property
    def stick_limit_mps2(self) -> float:
        """L = mu_s*g*kappa [m/s^2, true units]."""
        return math.exp(float(self.estimate[0]))

    @property
    def slip_deceleration_mps2(self) -> float:
        """D = mu_d*g*kappa [m/s^2, true units]."""
        return math.exp(float(self.estimate[1]))

    @property
    def gain(self) -> float:
        """Accelerometer gain k (measured / true)."""
        return math.exp(float(self.estimate[2]))

    @property
    def std(self) -> F64:
        """Standard deviations of ``theta`` (relative uncertainties of L, D, k)."""
        return np.asarray(np.sqrt(np.maximum(np.diag(self.covariance), 0.0)), np.float64)

    @property
    def static_friction(self) -> float:
        """Effective mu_s = L/(g*kappa) with the nominal g and kappa."""
        n = self.nominal
        return self.stick_limit_mps2 / (n.gravity_mps2 * n.friction_multiplier)

    @property
    def kinetic_friction(self) -> float:
        """Effective mu_d = D/(g*kappa) with the nominal g and kappa."""
        n = self.nominal
        return self.slip_deceleration_mps2 / (n.gravity_mps2 * n.friction_multiplier)

    def measured_part(self, theta: F64 | None = None) -> PartModel:
        """The part model the estimator runs on the measured carrier: ``L*k``, ``D*k``."""
        ln_l, ln_d, ln_k = self.estimate if theta is None else theta
        L = math.exp(float(ln_l + ln_k))
        D = min(math.exp(float(ln_d + ln_k)), L)
        g = self.nominal.gravity_mps2
        return PartModel(L / g, D / g, 1.0, g)

    def updated(
        self,
        weighted: tuple[F64, F64],
        estimate: F64,
        transits: int,
        operator_speeds: int,
        points: tuple[tuple[float, float], ...],
    ) -> PartBelief:
        """The belief a weighted particle set (theta n x 3, weights n) describes: its moments,
        ``estimate``, and ``BELIEF_PARTICLES`` of it resampled."""
        theta, weights = weighted
        mean = weights @ theta
        centred = theta - mean
        cov = (centred * weights[:, None]).T @ centred
        positions = (np.arange(BELIEF_PARTICLES) + 0.5) / BELIEF_PARTICLES  # systematic
        index = np.minimum(np.searchsorted(np.cumsum(weights), positions), len(theta) - 1)
        return replace(
            self,
            mean=np.asarray(mean, np.float64),
            covariance=np.asarray(0.5 * (cov + cov.T), np.float64),
            particles=np.asarray(theta[index], np.float64),
            estimate=np.asarray(estimate, np.float64),
            transits=transits,
            operator_speeds=operator_speeds,
            points=points,
        )


@dataclass(frozen=True)
class CarrierRun:
    """A periodic carrier model sampled for steady-speed runs: ``settle`` samples to forget the
    part's initial state, then the samples the mean speed is taken over. Sampling the model is
    most of the cost of a run and does not depend on the part, so it is done once per model."""

    t_s: F64
    velocity_mps: F64
    acceleration_mps2: F64
    settle: int

    @classmethod
    def of(cls, fit: HarmonicFit, dt_s: float, settle_periods: int, periods: int) -> CarrierRun:
        period = 1.0 / fit.base_frequency_hz
        n_settle = max(1, round(settle_periods * period / dt_s))
        n_avg = max(1, round(periods * period / dt_s))
        step = periods * period / n_avg
        t = fit.t_end_s - (n_settle + n_avg) * step + step * np.arange(n_settle + n_avg + 1)
        _, v, a = fit.evaluate(t)
        return cls(np.asarray(t, np.float64), v, a, n_settle)

    @classmethod
    def over(cls, fit: HarmonicFit, dt_s: float, span_s: float) -> CarrierRun:
        """``span_s`` (at least four response periods) ending at the fit's last sample, the first
        half to settle: the window the estimator's own uncertainty runs use."""
        period = 1.0 / fit.base_frequency_hz
        half = max(2, math.ceil(0.5 * span_s / period))
        return cls.of(fit, dt_s, half, half)

    def mean_speed(self, part: PartModel) -> float:
        """Mean speed of ``part`` started in stick, over the samples after ``settle``."""
        return self.motion(part)[0]

    def motion(self, part: PartModel) -> tuple[float, F64]:
        """``part``'s mean speed and its velocity at the samples after ``settle``."""
        out = StickSlipObserver(part).update(self.t_s, self.velocity_mps, self.acceleration_mps2)
        span = float(self.t_s[-1] - self.t_s[self.settle])
        return (
            float(np.sum(out.part_dx_m[self.settle + 1 :])) / span,
            np.asarray(out.part_v_mps[self.settle + 1 :], np.float64),
        )

    def speeds(self, belief: PartBelief, thetas: F64) -> F64:
        """True mean speeds for each row of ``thetas`` (measured-carrier runs divided by k)."""
        return np.array(
            [self.mean_speed(belief.measured_part(th)) / math.exp(float(th[2])) for th in thetas]
        )


@dataclass(frozen=True)
class SpeedPrediction:
    """A belief's steady mean speed on a carrier model [true m/s] (its estimate's) and its
    standard uncertainty [m/s]: the RMS deviation of the particles' speeds from it, or the wider
    side of their central 95 % over 1.96, whichever is larger;
    ``velocity_spread_mps``: the RMS deviation of the particles' part velocities over the run
    from the mean part's (the part model's share of the velocity's uncertainty)."""

    speed_mps: float
    uncertainty_mps: float
    velocity_spread_mps: float = 0.0


def predict_speed(
    carrier: HarmonicFit | CarrierRun,
    belief: PartBelief,
    dt_s: float = 1e-3,
    settle_periods: int = 10,
    periods: int = 20,
) -> SpeedPrediction:
    """See the module docstring. ``carrier``: a fit (sampled at ``dt_s`` for ``settle_periods`` +
    ``periods`` response periods) or an already sampled :class:`CarrierRun`."""
    run = (
        carrier
        if isinstance(carrier, CarrierRun)
        else CarrierRun.of(carrier, dt_s, settle_periods, periods)
    )

    def motion(theta: F64) -> tuple[float, F64]:
        k = math.exp(float(theta[2]))
        speed, velocity = run.motion(belief.measured_part(theta))
        return speed / k, velocity / k

    centre, u_centre = motion(belief.estimate)
    particles = belief.particles
    if len(particles) == 0:
        return SpeedPrediction(centre, 0.0)
    speeds = np.empty(len(particles))
    spread = 0.0
    for i, theta in enumerate(particles):
        speeds[i], velocity = motion(theta)
        spread += float(np.mean((velocity - u_centre) ** 2))
    # the speed is not linear in friction (less slip deceleration: much faster parts), so the
    # particles' speeds spread unevenly: the uncertainty covers the wider side of their central
    # 95 % at 1.96 sigma, and is never less than their RMS deviation
    rms = math.sqrt(float(np.mean((speeds - centre) ** 2)))
    low, high = np.quantile(speeds, [0.025, 0.975])
    wide = max(centre - float(low), float(high) - centre, 0.0) / 1.96
    return SpeedPrediction(centre, max(rms, wide), math.sqrt(spread / len(particles)))
