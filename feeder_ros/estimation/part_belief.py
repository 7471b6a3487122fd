"""What the estimator believes about the part model, and how sure it is (ROS-free).

With one-way coupling a part's motion on a given carrier depends on friction only through the stick
limit ``L = mu_s*g*kappa`` and the slip deceleration ``D = mu_d*g*kappa`` (``docs/model.md``,
section 8): ``mu_s``, ``mu_d``, ``kappa`` and ``g`` are not separately identifiable, only ``L`` and
``D``. An accelerometer gain ``k`` (measured = ``k`` * true) is exactly equivalent to a plant with
``L``, ``D`` and every velocity scaled by ``k``; only truth measured in length and time separates it
from friction. The belief is therefore a Gaussian over

    theta = (ln L, ln D, ln k)       (L, D in true m/s^2; k dimensionless)

with a mean and a covariance: before any calibration the nominal values with the stated relative
uncertainties (friction known to +-30 %, the gain to +-3 %), afterwards the posterior of
:mod:`~feeder_ros.estimation.calibration`. The estimator runs the part model on the *measured*
carrier with ``L*k`` and ``D*k`` and divides its speeds by ``k``.

:func:`predict_speed` gives the steady mean speed a belief predicts on a carrier model (a periodic
:class:`~feeder_ros.estimation.carrier_velocity.HarmonicFit`), its gradient with respect to
``theta`` (central differences over each parameter's own standard deviation, so that a kink such as
a slip onset inside the uncertain range is seen) and the standard uncertainty the belief's
covariance gives it: ``sigma^2 = J Sigma J^T``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from feeder_ros.estimation.carrier_velocity import HarmonicFit
from feeder_ros.estimation.stick_slip_observer import PartModel, StickSlipObserver
from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = [
    "CarrierRun",
    "PartBelief",
    "SpeedPrediction",
    "mean_speed_on",
    "predict_speed",
]

F64 = npt.NDArray[np.float64]
#: parameter names of theta, in order
THETA_NAMES = ("ln_stick_limit", "ln_slip_deceleration", "ln_accelerometer_gain")


def _check_fraction(name: str, value: float, upper: float) -> float:
    if not (is_number(value) and math.isfinite(value) and 0.0 <= value <= upper):
        raise ParameterError(f"{name}={value!r} must be finite and in [0, {upper:g}]")
    return float(value)


@dataclass(frozen=True)
class PartBelief:
    """A Gaussian belief over ``theta = (ln L, ln D, ln k)`` (see the module docstring).

    ``nominal`` carries ``kappa`` and ``g`` (to express ``L``, ``D`` as friction coefficients) and
    the nominal friction the prior is centred on. ``transits``/``operator_speeds``: how many
    measurements went into it.
    """

    nominal: PartModel
    mean: F64
    covariance: F64
    transits: int = 0
    operator_speeds: int = 0
    points: tuple[tuple[float, float], ...] = field(default=())  #: (f_d, amplitude) seen

    def __post_init__(self) -> None:
        mean = np.array(self.mean, dtype=np.float64).reshape(3)
        cov = np.array(self.covariance, dtype=np.float64).reshape(3, 3)
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise ParameterError(f"belief mean {mean} / covariance {cov.tolist()} not finite")
        cov = 0.5 * (cov + cov.T)
        if np.any(np.linalg.eigvalsh(cov) < -1e-12):
            raise ParameterError(f"belief covariance {cov.tolist()} is not positive semi-definite")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)

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
        return math.exp(float(self.mean[0]))

    @property
    def slip_deceleration_mps2(self) -> float:
        """D = mu_d*g*kappa [m/s^2, true units]."""
        return math.exp(float(self.mean[1]))

    @property
    def gain(self) -> float:
        """Accelerometer gain k (measured / true)."""
        return math.exp(float(self.mean[2]))

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
        ln_l, ln_d, ln_k = self.mean if theta is None else theta
        L = math.exp(float(ln_l + ln_k))
        D = min(math.exp(float(ln_d + ln_k)), L)
        g = self.nominal.gravity_mps2
        return PartModel(L / g, D / g, 1.0, g)

    def with_values(
        self,
        mean: F64,
        covariance: F64,
        transits: int,
        operator_speeds: int,
        points: tuple[tuple[float, float], ...],
    ) -> PartBelief:
        return replace(
            self,
            mean=mean,
            covariance=covariance,
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

    def mean_speed(self, part: PartModel) -> float:
        """Mean speed of ``part`` started in stick, over the samples after ``settle``."""
        out = StickSlipObserver(part).update(self.t_s, self.velocity_mps, self.acceleration_mps2)
        span = float(self.t_s[-1] - self.t_s[self.settle])
        return float(np.sum(out.part_dx_m[self.settle + 1 :])) / span


def mean_speed_on(
    fit: HarmonicFit, part: PartModel, dt_s: float, settle_periods: int, periods: int
) -> float:
    """Mean speed of ``part`` on the periodic carrier ``fit`` (in the fit's units): started in
    stick, run ``settle_periods`` response periods, then averaged over ``periods`` more."""
    return CarrierRun.of(fit, dt_s, settle_periods, periods).mean_speed(part)


@dataclass(frozen=True)
class SpeedPrediction:
    """A belief's steady mean speed on a carrier model [true m/s], its gradient with respect to
    ``theta`` and the standard uncertainty ``sqrt(J Sigma J^T)`` [m/s]."""

    speed_mps: float
    gradient: F64
    uncertainty_mps: float


def predict_speed(
    carrier: HarmonicFit | CarrierRun,
    belief: PartBelief,
    dt_s: float = 1e-3,
    settle_periods: int = 10,
    periods: int = 20,
    theta: F64 | None = None,
    steps: F64 | None = None,
) -> SpeedPrediction:
    """See the module docstring. ``carrier``: a fit (sampled at ``dt_s`` for ``settle_periods`` +
    ``periods`` response periods) or an already sampled :class:`CarrierRun`; ``theta``: evaluate
    there instead of at the belief's mean; ``steps``: the central-difference steps (default: each
    parameter's standard deviation, at least 1 %)."""
    run = (
        carrier
        if isinstance(carrier, CarrierRun)
        else CarrierRun.of(carrier, dt_s, settle_periods, periods)
    )
    th = np.array(belief.mean if theta is None else theta, dtype=np.float64)

    def speed(x: F64) -> float:
        return run.mean_speed(belief.measured_part(x)) / math.exp(float(x[2]))

    centre = speed(th)
    h = np.maximum(belief.std, 0.01) if steps is None else np.asarray(steps, np.float64)
    grad = np.zeros(3)
    for i in range(3):
        if h[i] <= 0.0:
            continue
        e = np.zeros(3)
        e[i] = h[i]
        grad[i] = (speed(th + e) - speed(th - e)) / (2.0 * h[i])
    variance = float(grad @ belief.covariance @ grad)
    return SpeedPrediction(centre, grad, math.sqrt(max(variance, 0.0)))
