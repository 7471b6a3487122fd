"""Drift-free carrier motion from its measured acceleration: a periodic (harmonic) model.

A carrier on springs has zero mean velocity, and once its transient has decayed (``c > 0``) a driven
feeder moves periodically. Integrating a noisy, biased accelerometer drifts; fitting the
acceleration with a Fourier series of the response period and integrating it term by term does not:

    a(t) = a0 + Re sum_k c_k e^{i k w (t - t_ref)},   k = 1..K,   w = 2*pi*f_base
    v(t) =      Re sum_k c_k/(i k w) e^{i k w (t - t_ref)}         (zero mean by construction)
    x(t) =     -Re sum_k c_k/(k w)^2 e^{i k w (t - t_ref)}

``a0`` absorbs the accelerometer bias (and any gravity component on the axis); it never reaches
``v``. The coefficients are a linear least-squares fit over a sliding window, so irregular sampling
and missing samples are handled exactly; white noise averages down as ``1/sqrt(N)``.

**The response period is not always the drive period.** The bilinear carrier (``K_f/K_b = 27`` in
the case study) has an effective natural frequency ``2*f_f*f_b/(f_f + f_b)`` of about 10.6 Hz;
driven at 20-45 Hz the damped carrier settles into *subharmonic* periodic motion (period 2, 3 or 4
drive periods, measured with the exact simulator). The base frequency is therefore ``f_d/n`` with
the period order ``n`` chosen from the data by the Bayesian information criterion
(:func:`select_period_order`): ``n`` = 1 when the response has the drive period, larger when it does
not. The undamped case study (``c = 0``) is chaotic: no period fits, and the fit's model-error
estimate (:attr:`HarmonicFit.model_error_rms_mps2`) says so.

The fit residual is split into white measurement noise and a smooth model error (transient, chaos,
wrong period) by its lag-one autocovariance: white noise is uncorrelated between samples, a smooth
error is almost fully correlated. The model error drives the estimator's confidences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from feeder_ros.estimation._harmonic_kernel import harmonic_lsq

__all__ = [
    "CarrierFitError",
    "HarmonicFit",
    "estimate_frequency",
    "fit_harmonics",
    "harmonic_count",
    "refine_frequency",
    "select_period_order",
]

F64 = npt.NDArray[np.float64]
C128 = npt.NDArray[np.complex128]
TWO_PI = 2.0 * math.pi


class CarrierFitError(ValueError):
    """The samples cannot support the requested fit; the message says why."""


@dataclass(frozen=True)
class HarmonicFit:
    """A periodic carrier model fitted to acceleration samples (see the module docstring).

    ``coefficients[k-1]`` is the complex amplitude ``c_k`` of harmonic ``k`` of
    ``base_frequency_hz`` (acceleration, m/s^2, whatever was measured); ``offset`` the fitted
    constant of the measured ``quantity`` (accelerometer bias, or displacement sensor zero).
    ``residual_rms_mps2`` splits into ``noise_rms_mps2`` (white) and ``model_error_rms_mps2``
    (smooth, not periodic with this base).
    """

    base_frequency_hz: float
    t_ref_s: float
    offset: float
    coefficients: C128
    residual_rms_mps2: float
    noise_rms_mps2: float
    model_error_rms_mps2: float
    signal_rms_mps2: float
    sample_count: int
    t_start_s: float
    t_end_s: float
    quantity: str = "acceleration"
    #: factor that expresses a residual of the measured quantity as acceleration (1, or the
    #: squared angular frequency of the strongest harmonic for displacement)
    to_acceleration: float = 1.0
    #: harmonics kept by :meth:`significant` (-1: all)
    significant_count: int = -1

    @property
    def offset_mps2(self) -> float:
        """The fitted accelerometer bias (0 for a displacement fit)."""
        return self.offset if self.quantity == "acceleration" else 0.0

    def measurement(self, t_s: npt.ArrayLike) -> F64:
        """The model of the measured quantity (offset included), e.g. to check new samples."""
        x, _, a = self.evaluate(t_s)
        return np.asarray(self.offset + (a if self.quantity == "acceleration" else x), np.float64)

    @property
    def harmonic_count(self) -> int:
        return int(self.coefficients.shape[0])

    @property
    def omega_rad_s(self) -> float:
        return TWO_PI * self.base_frequency_hz

    @property
    def span_s(self) -> float:
        return self.t_end_s - self.t_start_s

    def _phasors(self, t_s: npt.ArrayLike) -> tuple[C128, F64]:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        k = np.arange(1, self.harmonic_count + 1, dtype=np.float64)
        theta = self.omega_rad_s * (t - self.t_ref_s)
        return _phasor_table(theta, self.harmonic_count), k * self.omega_rad_s

    def evaluate(self, t_s: npt.ArrayLike) -> tuple[F64, F64, F64]:
        """(displacement m, velocity m/s, acceleration m/s^2) of the periodic model at ``t_s``.

        The acceleration excludes ``offset_mps2`` (it is the carrier's, not the sensor's).
        """
        E, kw = self._phasors(t_s)
        a_c = E * self.coefficients
        acc = a_c.real.sum(axis=1)
        vel = (a_c / (1j * kw)).real.sum(axis=1)
        disp = (-a_c / kw**2).real.sum(axis=1)
        return (
            np.asarray(disp, np.float64),
            np.asarray(vel, np.float64),
            np.asarray(acc, np.float64),
        )

    def velocity(self, t_s: npt.ArrayLike) -> F64:
        return self.evaluate(t_s)[1]

    def acceleration(self, t_s: npt.ArrayLike) -> F64:
        return self.evaluate(t_s)[2]

    def significant(self, threshold_sigma: float) -> HarmonicFit:
        """This fit with the harmonics indistinguishable from noise set to zero.

        A harmonic is kept when ``|c_k| > threshold_sigma * sigma_c`` (``sigma_c``: the standard
        error of one real coefficient); pure-noise harmonics pass ``3 sigma`` with probability
        ``exp(-4.5) = 1 %``. Dropping them cuts the noise of the modelled acceleration, which at the
        stick limit decides the slip instants, roughly by ``sqrt(K_kept/K)``.
        """
        if threshold_sigma <= 0.0:
            return self
        limit = threshold_sigma * self.coefficient_noise_mps2 * self.to_acceleration_noise()
        keep = np.abs(self.coefficients) > limit
        kept = np.where(keep, self.coefficients, 0.0).astype(np.complex128)
        return replace(self, coefficients=kept, significant_count=int(np.count_nonzero(keep)))

    def to_acceleration_noise(self) -> npt.NDArray[np.float64] | float:
        """Per-harmonic factor from the coefficient noise to acceleration-coefficient noise."""
        if self.quantity != "displacement":
            return 1.0
        kw = np.arange(1, self.harmonic_count + 1, dtype=np.float64) * self.omega_rad_s
        return np.asarray(kw**2 / self.to_acceleration, np.float64)

    @property
    def coefficient_noise_mps2(self) -> float:
        """Standard error of one real coefficient from the white noise: ``sigma*sqrt(2/N)``."""
        return self.noise_rms_mps2 * math.sqrt(2.0 / max(self.sample_count, 1))

    @property
    def acceleration_uncertainty_mps2(self) -> float:
        """1-sigma uncertainty of the modelled acceleration at one instant (noise + model error)."""
        count = self.harmonic_count if self.significant_count < 0 else self.significant_count
        noise = self.coefficient_noise_mps2 * math.sqrt(count)
        return math.hypot(noise, self.model_error_rms_mps2)

    @property
    def velocity_uncertainty_mps(self) -> float:
        """1-sigma uncertainty of the modelled velocity (noise through 1/(k w), model error at
        w)."""
        k = np.arange(1, self.harmonic_count + 1, dtype=np.float64)
        noise = self.coefficient_noise_mps2 * math.sqrt(
            float(np.sum(1.0 / (k * self.omega_rad_s) ** 2))
        )
        return math.hypot(noise, self.model_error_rms_mps2 / self.omega_rad_s)


def _phasor_table(theta: F64, K: int) -> C128:
    """``exp(i*k*theta)`` for k = 1..K as an (N, K) table: powers by repeated products (cheaper than
    N*K complex exponentials; the round-off grows like ``k*eps``, far below any noise here)."""
    z = np.exp(1j * np.mod(theta, TWO_PI))
    return np.cumprod(np.broadcast_to(z[:, None], (z.size, K)), axis=1)


def harmonic_count(base_frequency_hz: float, sample_rate_hz: float, max_harmonic_hz: float) -> int:
    """Harmonics of ``base_frequency_hz`` kept below ``min(max_harmonic_hz,
    0.45*sample_rate_hz)``."""
    top = min(max_harmonic_hz, 0.45 * sample_rate_hz)
    return max(1, math.floor(top / base_frequency_hz + 1e-9))


def fit_harmonics(
    t_s: npt.ArrayLike,
    accel_mps2: npt.ArrayLike,
    base_frequency_hz: float,
    harmonics: int,
    t_ref_s: float = 0.0,
    quantity: str = "acceleration",
) -> HarmonicFit:
    """Least-squares fit of ``a0 + Re sum_{k<=harmonics} c_k e^{i k w (t - t_ref)}`` to the
    samples of ``quantity`` (``"acceleration"``, or ``"displacement"`` from a displacement sensor:
    the result is converted to acceleration coefficients, the same carrier model)."""
    t = np.ascontiguousarray(t_s, dtype=np.float64).ravel()
    a = np.ascontiguousarray(accel_mps2, dtype=np.float64).ravel()
    if t.shape != a.shape:
        raise CarrierFitError(f"{t.size} times but {a.size} accelerations")
    if not (base_frequency_hz > 0.0 and math.isfinite(base_frequency_hz)):
        raise CarrierFitError(f"base_frequency_hz={base_frequency_hz!r} must be finite and > 0")
    K = int(harmonics)
    p = 2 * K + 1
    if K < 1 or t.size < p + 2:
        raise CarrierFitError(f"{t.size} samples cannot fit {K} harmonics ({p} unknowns)")
    theta = np.mod(TWO_PI * base_frequency_hz * (t - t_ref_s), TWO_PI)
    beta = np.zeros(p)
    sums = np.zeros(3)
    if harmonic_lsq(theta, a, K, beta, sums) != 0:
        raise CarrierFitError(
            f"harmonic fit is singular ({t.size} samples, {K} harmonics of {base_frequency_hz} Hz)"
        )
    n = t.size
    var = max(float(sums[0]), 0.0) / n
    smooth = min(max(float(sums[1]) / max(n - 1, 1), 0.0), var)
    coefficients = (beta[1 : K + 1] - 1j * beta[K + 1 :]).astype(np.complex128)
    scale = 1.0
    if quantity == "displacement":
        # x = Re sum d_k e^{ik w t}  =>  a = Re sum -(k w)^2 d_k e^{ik w t}; residuals are expressed
        # in acceleration at the strongest harmonic (where the motion and its error live)
        kw = np.arange(1, K + 1, dtype=np.float64) * TWO_PI * base_frequency_hz
        scale = float(kw[int(np.argmax(np.abs(coefficients)))] ** 2)
        coefficients = (-(kw**2) * coefficients).astype(np.complex128)
    elif quantity != "acceleration":
        raise CarrierFitError(f"quantity={quantity!r} is not acceleration or displacement")
    return HarmonicFit(
        base_frequency_hz=float(base_frequency_hz),
        t_ref_s=float(t_ref_s),
        offset=float(beta[0]),
        coefficients=coefficients,
        residual_rms_mps2=scale * math.sqrt(var),
        noise_rms_mps2=scale * math.sqrt(var - smooth),
        model_error_rms_mps2=scale * math.sqrt(smooth),
        signal_rms_mps2=scale * math.sqrt(float(sums[2]) / n),
        sample_count=int(t.size),
        t_start_s=float(t[0]),
        t_end_s=float(t[-1]),
        quantity=quantity,
        to_acceleration=scale,
    )


def select_period_order(
    t_s: npt.ArrayLike,
    accel_mps2: npt.ArrayLike,
    drive_frequency_hz: float,
    max_order: int,
    max_harmonic_hz: float,
    t_ref_s: float = 0.0,
    quantity: str = "acceleration",
) -> tuple[int, HarmonicFit]:
    """The period order ``n`` (response period ``n/f_d``) with the least BIC, and its fit.

    ``BIC = N*ln(rms^2) + p*ln(N)``: a longer period only wins when its extra harmonics explain far
    more than noise would (they always lower the residual a little, and orders that divide each
    other nest).
    """
    t = np.ascontiguousarray(t_s, dtype=np.float64).ravel()
    a = np.ascontiguousarray(accel_mps2, dtype=np.float64).ravel()
    if t.size < 8:
        raise CarrierFitError(f"{t.size} samples are too few to choose a period")
    rate = 1.0 / float(np.median(np.diff(t)))
    best: tuple[float, int, HarmonicFit] | None = None
    for order in range(1, max(1, max_order) + 1):
        base = drive_frequency_hz / order
        if order > 1 and t[-1] - t[0] < 2.0 / base:
            break  # fewer than two periods of this order in the window: cannot tell
        K = min(harmonic_count(base, rate, max_harmonic_hz), (t.size - 3) // 2 - 1)
        if K < 1:
            break
        fit = fit_harmonics(t, a, base, K, t_ref_s, quantity)
        # residual relative to the signal: the same ranking in any units (displacement fits are
        # scaled to acceleration)
        ratio = fit.residual_rms_mps2 / max(fit.signal_rms_mps2, 1e-300)
        bic = t.size * math.log(max(ratio, 1e-300) ** 2) + (2 * K + 1) * math.log(t.size)
        if best is None or bic < best[0]:
            best = (bic, order, fit)
    if best is None:
        raise CarrierFitError("no period order could be fitted")
    return best[1], best[2]


def estimate_frequency(
    t_s: npt.ArrayLike,
    accel_mps2: npt.ArrayLike,
    min_hz: float,
    max_hz: float,
    harmonics: int = 4,
) -> float:
    """Frequency of the strongest spectral line in ``[min_hz, max_hz]``, refined to a small fraction
    of a bin: Hann-windowed, zero-padded FFT peak, then the frequency that minimises the residual of
    a
    ``harmonics``-term fit (a bounded scalar search over +-1.5 FFT bins)."""
    t = np.ascontiguousarray(t_s, dtype=np.float64).ravel()
    a = np.ascontiguousarray(accel_mps2, dtype=np.float64).ravel()
    if t.size < 16:
        raise CarrierFitError(f"{t.size} samples are too few to estimate a frequency")
    dt = float(np.median(np.diff(t)))
    grid = t[0] + dt * np.arange(math.floor((t[-1] - t[0]) / dt) + 1)
    y = np.interp(grid, t, a)
    y = (y - y.mean()) * np.hanning(y.size)
    nfft = 1 << (8 * y.size - 1).bit_length()
    spectrum = np.abs(np.fft.rfft(y, nfft))
    freqs = np.fft.rfftfreq(nfft, dt)
    band = np.flatnonzero((freqs >= min_hz) & (freqs <= max_hz))
    if band.size < 3:
        raise CarrierFitError(f"band [{min_hz}, {max_hz}] Hz holds no spectral lines")
    i = int(band[np.argmax(spectrum[band])])
    f0 = float(freqs[i])
    if 0 < i < spectrum.size - 1:
        lm, l0, lp = np.log(spectrum[i - 1 : i + 2] + 1e-300)
        denom = lm - 2.0 * l0 + lp
        if denom < 0.0:
            f0 += 0.5 * (lm - lp) / denom * float(freqs[1] - freqs[0])
    bin_hz = 1.0 / (grid[-1] - grid[0] + dt)
    rate = 1.0 / dt
    K = max(1, min(harmonics, harmonic_count(f0, rate, 0.45 * rate)))

    def cost(f: float) -> float:
        return fit_harmonics(t, a, f, K, t[0]).residual_rms_mps2

    lo, hi = max(f0 - 1.5 * bin_hz, 0.5 * f0), f0 + 1.5 * bin_hz
    result = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6 * f0})
    return float(result.x) if result.success else f0


def refine_frequency(
    t_s: npt.ArrayLike,
    accel_mps2: npt.ArrayLike,
    drive_frequency_hz: float,
    period_order: int,
    max_harmonic_hz: float,
    relative_range: float,
    t_ref_s: float = 0.0,
) -> float:
    """The drive frequency in ``f0*(1 +- relative_range)`` that minimises the residual of the full
    harmonic model of order ``period_order`` (every harmonic line votes; far finer than an FFT
    bin)."""
    t = np.ascontiguousarray(t_s, dtype=np.float64).ravel()
    a = np.ascontiguousarray(accel_mps2, dtype=np.float64).ravel()
    if t.size < 16:
        raise CarrierFitError(f"{t.size} samples are too few to refine a frequency")
    rate = 1.0 / float(np.median(np.diff(t)))
    f0 = float(drive_frequency_hz)
    n = max(1, int(period_order))
    K = min(
        harmonic_count(f0 * (1.0 + relative_range) / n, rate, max_harmonic_hz),
        (t.size - 3) // 2 - 1,
    )
    if K < 1:
        raise CarrierFitError("window too short to refine the frequency")

    def cost(f: float) -> float:
        return fit_harmonics(t, a, f / n, K, t_ref_s).residual_rms_mps2

    lo, hi = f0 * (1.0 - relative_range), f0 * (1.0 + relative_range)
    result = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-7 * f0})
    return float(result.x) if result.success else f0
