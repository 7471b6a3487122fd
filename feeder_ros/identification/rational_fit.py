"""Rational transfer-function fit of a speed sweep: mean part speed against drive frequency.

The paper (Section 4, Eqs. 21-23) identifies a continuous-time model of the mean part speed
``V_V`` driven by the force ``F = A_r sin(omega_d t)``::

    V_V = G(i omega) F(i omega) + e                                   (Eq. 21)
    G(s) = gain * prod_i (s - z_i) / prod_j (s - p_j)                 (Eq. 22)
    theta = argmin sum_k mu_k (v_k - G(k, theta) F(k))^2              (Eq. 23)

A speed sweep measures one number per drive frequency: the mean speed, a magnitude without a
phase. Eq. 23 is therefore read here for magnitudes only::

    theta = argmin sum_k mu_k (v_k - |G(j w_k)| A)^2,   w_k = 2 pi f_k [rad/s], A [N]

The phase of ``G`` is not observable from such data. Poles are kept stable (Re p < 0), and since
``|j w - z| = |j w + conj(z)|`` a zero and its mirror image in the imaginary axis give the same
magnitude: zeros are reported minimum-phase (Re z <= 0), whatever the true system's are. ``G`` has
real coefficients (complex poles and zeros come in conjugate pairs).

Method: a linear initial estimate (Levy's linearisation with Sanathanan-Koerner re-weighting) of
``|G|^2 = N(w^2) / D(w^2)``, factorised into left-half-plane roots, and seeded random starts are
each refined by :func:`scipy.optimize.least_squares` on Eq. 23 in a parametrisation that can only
express stable poles and minimum-phase zeros (see :func:`fit_rational`); the best refinement wins.
Frequencies are scaled by a reference frequency (the geometric centre of the band) and speeds by
their RMS, so that the numbers the optimiser sees are of order one.

(About 900 lines: the model, the fit and the comparison of model orders share this module's
private data checks and parameter layout; a module of their own would import them all.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares, minimize_scalar

__all__ = [
    "FREQUENCY_RESOLUTION_HZ",
    "FitResult",
    "IdentificationError",
    "OrderScore",
    "RationalModel",
    "best_order",
    "compare_orders",
    "distinct_frequencies",
    "fit_percent",
    "fit_rational",
    "min_distinct_frequencies",
]

F64 = NDArray[np.float64]
C128 = NDArray[np.complex128]

_LOG_BOUND = 20.0  # |log| of a normalised root scale: roots within e^-20 .. e^20 x w_ref
_CONJUGATE_RTOL = 1e-9  # relative tolerance for "these two roots are a conjugate pair"
#: frequencies closer than this are one frequency (Hz): points 1e-12 Hz apart are repeats of one
#: setting, not a frequency response (a fit over them only fits noise)
FREQUENCY_RESOLUTION_HZ = 1e-6


class IdentificationError(ValueError):
    """Data, orders, settings or a model that identification cannot accept; the message names the
    offending value and why."""


# --------------------------------------------------------------------------- validation helpers


def _real(field: str, value: object) -> float:
    """``value`` as a finite float (bools and strings are refused)."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise IdentificationError(f"{field}={value!r} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise IdentificationError(f"{field}={number!r} is not finite")
    return number


def _vector(name: str, values: ArrayLike) -> F64:
    """A non-empty 1-D float array without NaN/inf (the message names the first bad index)."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"{name} is not an array of numbers: {exc}") from None
    if array.ndim != 1 or array.size == 0:
        raise IdentificationError(f"{name} must be a non-empty 1-D array; got shape {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        index = int(bad[0])
        raise IdentificationError(f"{name}[{index}] = {float(array[index])!r} is not finite")
    return array


def _order(zeros: int, poles: int) -> tuple[int, int]:
    for name, value in (("zeros", zeros), ("poles", poles)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise IdentificationError(f"{name}={value!r} is not an integer")
        if value < 0:
            raise IdentificationError(f"{name}={value} must be >= 0")
    if zeros > poles:
        raise IdentificationError(
            f"zeros={zeros} > poles={poles}: G(s) would be improper (|G| growing without bound)"
        )
    return int(zeros), int(poles)


def _roots(field: str, values: Sequence[complex]) -> tuple[complex, ...]:
    roots: list[complex] = []
    for index, value in enumerate(values):
        if isinstance(value, bool) or not isinstance(value, int | float | complex | np.number):
            raise IdentificationError(f"{field}[{index}]={value!r} is not a number")
        root = complex(value)
        if not (math.isfinite(root.real) and math.isfinite(root.imag)):
            raise IdentificationError(f"{field}[{index}] = {root!r} is not finite")
        roots.append(root)
    _require_conjugate_pairs(field, roots)
    return tuple(roots)


def _require_conjugate_pairs(field: str, roots: Sequence[complex]) -> None:
    """Real coefficients: every root off the real axis has its conjugate among the roots."""
    unmatched = [index for index, root in enumerate(roots) if root.imag != 0.0]
    while unmatched:
        index = unmatched.pop(0)
        root = roots[index]
        tolerance = _CONJUGATE_RTOL * max(abs(root), 1.0)
        partner = next(
            (j for j in unmatched if abs(roots[j] - root.conjugate()) <= tolerance), None
        )
        if partner is None:
            raise IdentificationError(
                f"{field}[{index}] = {root!r} has no complex-conjugate partner: "
                "G(s) must have real coefficients"
            )
        unmatched.remove(partner)


# --------------------------------------------------------------------------- the model


@dataclass(frozen=True)
class RationalModel:
    """G(s) = gain * prod(s - z_i) / prod(s - p_j), s in rad/s (Eq. 22); input = drive force
    amplitude [N], output = mean part speed [m/s]: predicted speed = |G(j 2 pi f)| * amplitude_n.

    Validated on construction: finite numbers, stable poles (Re p < 0), no more zeros than poles
    (proper), conjugate pairs (real coefficients).
    """

    gain: float
    zeros: tuple[complex, ...] = ()
    poles: tuple[complex, ...] = ()

    def __post_init__(self) -> None:
        gain = _real("gain", self.gain)
        zeros = _roots("zeros", self.zeros)
        poles = _roots("poles", self.poles)
        for index, pole in enumerate(poles):
            if not pole.real < 0.0:
                raise IdentificationError(
                    f"poles[{index}] = {pole!r} is not stable: needs Re(p) < 0"
                )
        if len(zeros) > len(poles):
            raise IdentificationError(
                f"{len(zeros)} zeros > {len(poles)} poles: G(s) would be improper"
            )
        object.__setattr__(self, "gain", gain)
        object.__setattr__(self, "zeros", zeros)
        object.__setattr__(self, "poles", poles)

    @property
    def order(self) -> tuple[int, int]:
        """(number of zeros, number of poles)."""
        return len(self.zeros), len(self.poles)

    def response(self, frequency_hz: ArrayLike) -> C128:
        """G(j 2 pi f), same shape as ``frequency_hz``."""
        s = 2j * np.pi * np.asarray(frequency_hz, dtype=np.float64)
        zeros = np.asarray(self.zeros, dtype=np.complex128)
        poles = np.asarray(self.poles, dtype=np.complex128)
        numerator = np.prod(s[..., np.newaxis] - zeros, axis=-1)
        denominator = np.prod(s[..., np.newaxis] - poles, axis=-1)
        return np.asarray(self.gain * numerator / denominator, dtype=np.complex128)

    def magnitude(self, frequency_hz: ArrayLike) -> F64:
        """|G(j 2 pi f)| [m/s per N]: times the force amplitude, the predicted mean speed."""
        return np.abs(self.response(frequency_hz)).astype(np.float64)

    def peak_frequency_hz(self, low_hz: float, high_hz: float) -> float:
        """Frequency of the largest |G| in [low_hz, high_hz] (ties: the lowest).

        A dense grid (2001 points) finds the best cell; a bounded scalar search inside the cells
        next to it polishes the maximum to ~1e-9 of the band.
        """
        low, high = _real("low_hz", low_hz), _real("high_hz", high_hz)
        if not 0.0 < low < high:
            raise IdentificationError(
                f"peak search band low_hz={low:g} .. high_hz={high:g} needs 0 < low < high"
            )
        grid = np.linspace(low, high, 2001)
        values = self.magnitude(grid)
        best = int(np.argmax(values))
        left, right = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
        polished = minimize_scalar(
            lambda f: -float(self.magnitude(f)),
            bounds=(float(left), float(right)),
            method="bounded",
            options={"xatol": 1e-9 * high},
        )
        candidate = float(polished.x)
        if self.magnitude(candidate) > values[best]:
            return candidate
        return float(grid[best])

    def to_dict(self) -> dict[str, Any]:
        """YAML/JSON-safe form: ``{gain, zeros: [[re, im], ...], poles: [[re, im], ...]}``."""
        return {
            "gain": float(self.gain),
            "zeros": [[float(z.real), float(z.imag)] for z in self.zeros],
            "poles": [[float(p.real), float(p.imag)] for p in self.poles],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RationalModel:
        """The model of :meth:`to_dict`; IdentificationError naming the bad field otherwise."""
        if not isinstance(data, Mapping):
            raise IdentificationError(f"model must be a mapping; got {type(data).__name__}")
        missing = [key for key in ("gain", "zeros", "poles") if key not in data]
        if missing:
            raise IdentificationError(f"missing field(s) {', '.join(missing)}")
        gain = _real("gain", data["gain"])
        zeros = _complex_list("zeros", data["zeros"])
        poles = _complex_list("poles", data["poles"])
        return cls(gain, zeros, poles)


def _complex_list(field: str, value: object) -> tuple[complex, ...]:
    if not isinstance(value, list | tuple):
        raise IdentificationError(f"{field}={value!r} is not a list of [re, im] pairs")
    roots: list[complex] = []
    for index, pair in enumerate(value):
        if not isinstance(pair, list | tuple) or len(pair) != 2:
            raise IdentificationError(f"{field}[{index}]={pair!r} is not an [re, im] pair")
        real = _real(f"{field}[{index}][0]", pair[0])
        imag = _real(f"{field}[{index}][1]", pair[1])
        roots.append(complex(real, imag))
    return tuple(roots)


# --------------------------------------------------------------------------- goodness of fit


def fit_percent(measured: ArrayLike, predicted: ArrayLike) -> float:
    """Normalised RMS fit in percent, ``100 * (1 - ||y - yhat|| / ||y - mean(y)||)``.

    This is MATLAB's ``compare`` / ``goodnessOfFit(..., 'NRMSE')`` measure behind the paper's
    63 % and 50 %: 100 is a perfect fit, 0 is no better than the mean, negative is worse.
    """
    y = _vector("measured", measured)
    y_hat = _vector("predicted", predicted)
    if y.shape != y_hat.shape:
        raise IdentificationError(
            f"measured has {y.size} values but predicted has {y_hat.size}: lengths must match"
        )
    spread = float(np.linalg.norm(y - y.mean()))
    if spread == 0.0:
        raise IdentificationError(
            f"all measured values equal {float(y[0])!r}: the normalised fit is undefined"
        )
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / spread)


# --------------------------------------------------------------------------- parametrisation


@dataclass(frozen=True)
class _Layout:
    """Where each factor's parameters sit in theta (all in units of the reference frequency).

    theta = [log g, zero quadratics (u, v) ..., zero real w?, pole quadratics ..., pole real w?]
    A quadratic s^2 + a1 s + a0 with a1 = floor + e^u, a0 = e^v has positive coefficients, hence
    both roots in the open left half-plane, complex or real; a real factor s + e^w has its root at
    -e^w. Every theta is thus a stable, minimum-phase G, and a pair can move between real and
    complex roots continuously. ``floor`` (the resolution of the sweep, see fit_rational) keeps a
    quadratic's bandwidth a1 = 2 zeta w_n from shrinking below what the data can resolve.
    """

    zeros: int
    poles: int
    floor: float = 0.0

    @property
    def size(self) -> int:
        return 1 + self.zeros + self.poles

    def factors(self) -> list[tuple[int, int, float]]:
        """(first index, kind 2 = quadratic / 1 = real, sign +1 zero / -1 pole) per factor."""
        result: list[tuple[int, int, float]] = []
        index = 1
        for count, sign in ((self.zeros, 1.0), (self.poles, -1.0)):
            for _ in range(count // 2):
                result.append((index, 2, sign))
                index += 2
            if count % 2:
                result.append((index, 1, sign))
                index += 1
        return result

    @cached_property
    def quadratics(self) -> tuple[NDArray[np.intp], F64]:
        """First indices and signs of the quadratic factors (vectorised evaluation)."""
        return self._indices(2)

    @cached_property
    def reals(self) -> tuple[NDArray[np.intp], F64]:
        """First indices and signs of the real factors."""
        return self._indices(1)

    def _indices(self, kind: int) -> tuple[NDArray[np.intp], F64]:
        chosen = [(index, sign) for index, k, sign in self.factors() if k == kind]
        first = np.asarray([index for index, _ in chosen], dtype=np.intp)
        return first, np.asarray([sign for _, sign in chosen], dtype=np.float64)


def _log_magnitude(layout: _Layout, theta: F64, x: F64) -> tuple[F64, F64]:
    """log |G'(j w')| and its gradient in theta at x = w'^2 (normalised frequency squared).

    Quadratic: |(j w)^2 + a1 j w + a0|^2 = (a0 - x)^2 + a1^2 x; real: |j w + b|^2 = x + b^2.
    """
    gradient = np.zeros((x.size, theta.size))
    gradient[:, 0] = 1.0
    log_g = np.full_like(x, theta[0])
    column = x[:, np.newaxis]
    first, sign = layout.quadratics
    if first.size:
        grow = np.exp(theta[first])
        a1, a0 = layout.floor + grow, np.exp(theta[first + 1])
        q = (a0 - column) ** 2 + a1 * a1 * column
        log_g += 0.5 * np.log(q) @ sign
        gradient[:, first] = sign * a1 * grow * column / q
        gradient[:, first + 1] = sign * a0 * (a0 - column) / q
    first, sign = layout.reals
    if first.size:
        b2 = np.exp(2.0 * theta[first])
        r = column + b2
        log_g += 0.5 * np.log(r) @ sign
        gradient[:, first] = sign * b2 / r
    return log_g, gradient


def _quadratic_roots(a1: float, a0: float) -> tuple[complex, complex]:
    """Roots of s^2 + a1 s + a0 (a1, a0 > 0), without cancellation: both have Re < 0."""
    discriminant = a1 * a1 - 4.0 * a0
    if discriminant >= 0.0:
        q = -0.5 * (a1 + math.sqrt(discriminant))
        return complex(q, 0.0), complex(a0 / q, 0.0)
    imag = 0.5 * math.sqrt(-discriminant)
    return complex(-0.5 * a1, imag), complex(-0.5 * a1, -imag)


def _model_from_theta(
    layout: _Layout, theta: F64, omega_ref: float, speed_scale: float
) -> RationalModel:
    """G(s) = speed_scale * G'(s / omega_ref), with G'(s') = e^theta0 * prod(s'-z')/prod(s'-p')."""
    roots: dict[float, list[complex]] = {1.0: [], -1.0: []}
    for index, kind, sign in layout.factors():
        if kind == 2:
            a1 = layout.floor + math.exp(theta[index])
            pair = _quadratic_roots(a1, math.exp(theta[index + 1]))
            roots[sign].extend(root * omega_ref for root in pair)
        else:
            roots[sign].append(complex(-math.exp(theta[index]) * omega_ref, 0.0))
    gain = speed_scale * math.exp(theta[0]) * omega_ref ** (layout.poles - layout.zeros)
    return RationalModel(gain, tuple(roots[1.0]), tuple(roots[-1.0]))


# --------------------------------------------------------------------------- starting points


def _quadratic_theta(layout: _Layout, a1: float, a0: float) -> list[float]:
    """(u, v) of s^2 + a1 s + a0, a1 raised to just above the layout's floor if needed."""
    grow = max(a1 - layout.floor, 0.05 * max(a1, layout.floor), 1e-300)
    return [math.log(grow), math.log(max(a0, 1e-300))]


def _factor_parameters(layout: _Layout, x_roots: C128, count: int) -> list[float]:
    """Parameters of ``count`` factors (pairs, then one real if odd) whose |.|^2 has roots x_roots.

    A quadratic's |.|^2 = x^2 + (a1^2 - 2 a0) x + a0^2 has the root pair {x1, x2}: a0 = sqrt(x1 x2),
    a1 = sqrt(2 a0 - x1 - x2); a real factor's x + b^2 has the root -b^2. Roots that no stable
    factor can produce (they come from a polynomial that is negative somewhere) are moved to the
    nearest producible ones; this is only a starting point. Missing roots (a leading coefficient
    of zero) become far-away factors, flat over the band.
    """
    far = complex(-math.exp(_LOG_BOUND), 0.0)
    roots = list(x_roots) + [far] * (count - len(x_roots))
    is_real = [abs(r.imag) <= 1e-9 * max(abs(r), 1.0) for r in roots]
    pairs = [
        (r, r.conjugate())
        for r, real in zip(roots, is_real, strict=True)
        if r.imag > 0 and not real
    ]
    reals = sorted(r.real for r, real in zip(roots, is_real, strict=True) if real)
    single = reals.pop(0) if count % 2 and reals else -1.0  # most negative: the best -b^2
    pairs += [(complex(reals[i]), complex(reals[i + 1])) for i in range(0, len(reals) - 1, 2)]
    pairs += [(far, far)] * (count // 2 - len(pairs))
    theta: list[float] = []
    for x1, x2 in pairs[: count // 2]:
        a0 = math.sqrt(max(abs((x1 * x2).real), 1e-300))
        a1 = math.sqrt(max(2.0 * a0 - (x1 + x2).real, 0.0))
        theta += _quadratic_theta(layout, a1, a0)
    if count % 2:
        theta.append(0.5 * math.log(max(abs(single), 1e-300)))
    return theta


def _levy_start(layout: _Layout, x: F64, y: F64, sqrt_mu: F64, iterations: int = 10) -> F64 | None:
    """Linear estimate of |G'|^2 = N(x) / D(x), D(0) = 1 (Levy), re-weighted by 1/D (Sanathanan-
    Koerner), factorised into stable, minimum-phase factors; None when it breaks down."""
    target = np.maximum(y, 0.0) ** 2
    nz, npoles = layout.zeros, layout.poles
    powers_n = x[:, np.newaxis] ** np.arange(nz + 1)
    powers_d = x[:, np.newaxis] ** np.arange(1, npoles + 1)
    matrix = np.hstack([powers_n, -target[:, np.newaxis] * powers_d])
    denominator = np.ones_like(x)
    coefficients = np.zeros(matrix.shape[1])
    for _ in range(iterations):
        weight = sqrt_mu / np.abs(denominator)
        scaled = matrix * weight[:, np.newaxis]
        norms = np.linalg.norm(scaled, axis=0)
        norms[norms == 0.0] = 1.0
        solution, *_ = np.linalg.lstsq(scaled / norms, target * weight, rcond=None)
        coefficients = solution / norms
        denominator = 1.0 + powers_d @ coefficients[nz + 1 :]
        if not np.all(np.isfinite(denominator)) or np.any(denominator <= 0.0):
            return None
    numerator_c = coefficients[: nz + 1]
    denominator_c = np.concatenate([[1.0], coefficients[nz + 1 :]])
    if not np.all(np.isfinite(numerator_c)):
        return None
    zero_x = np.roots(numerator_c[::-1]) if nz else np.zeros(0)
    pole_x = np.roots(denominator_c[::-1]) if npoles else np.zeros(0)
    theta = [0.0]  # the gain is set to its optimum for the shape in _refine
    theta += _factor_parameters(layout, np.asarray(zero_x, np.complex128), nz)
    theta += _factor_parameters(layout, np.asarray(pole_x, np.complex128), npoles)
    result = np.asarray(theta, dtype=np.float64)
    return result if np.all(np.isfinite(result)) else None


def _random_start(layout: _Layout, x: F64, rng: np.random.Generator) -> F64:
    """Roots spread log-uniformly over the band widened by a factor e either side; damping
    ratios log-uniform in 0.03 .. 2 (over 1: a pair of real roots)."""
    w_low, w_high = math.sqrt(float(x.min())), math.sqrt(float(x.max()))
    span = (math.log(w_low) - 1.0, math.log(w_high) + 1.0)
    theta = np.zeros(layout.size)
    for index, kind, _ in layout.factors():
        w = math.exp(rng.uniform(*span))
        if kind == 2:
            damping = math.exp(rng.uniform(math.log(0.03), math.log(2.0)))
            theta[index : index + 2] = _quadratic_theta(layout, 2.0 * damping * w, w * w)
        else:
            theta[index] = math.log(w)
    return theta


# --------------------------------------------------------------------------- the fit


@dataclass(frozen=True, eq=False)
class FitResult:
    """A fitted model and the data it was fitted to (Eq. 23 with weights mu_k).

    ``fit_percent`` and ``residual_rms_mps`` are unweighted, over the points with weight > 0.
    """

    model: RationalModel
    zeros: int
    poles: int
    frequency_hz: F64
    measured_speed_mps: F64
    amplitude_n: float
    fit_percent: float
    residual_rms_mps: float

    @property
    def predicted_speed_mps(self) -> F64:
        """|G(j 2 pi f_k)| * amplitude_n at the fitted frequencies."""
        return self.model.magnitude(self.frequency_hz) * self.amplitude_n


@dataclass(frozen=True)
class _Data:
    frequency_hz: F64
    speed_mps: F64
    weights: F64
    amplitude_n: float


def _checked_data(
    frequency_hz: ArrayLike,
    speed_mps: ArrayLike,
    amplitude_n: float,
    weights: ArrayLike | None,
) -> _Data:
    frequency = _vector("frequency_hz", frequency_hz)
    speed = _vector("speed_mps", speed_mps)
    if frequency.size != speed.size:
        raise IdentificationError(
            f"frequency_hz has {frequency.size} values but speed_mps has {speed.size}: "
            "lengths must match"
        )
    bad = np.flatnonzero(frequency <= 0.0)
    if bad.size:
        index = int(bad[0])
        raise IdentificationError(
            f"frequency_hz[{index}] = {float(frequency[index])!r} must be > 0 Hz"
        )
    amplitude = _real("amplitude_n", amplitude_n)
    if amplitude <= 0.0:
        raise IdentificationError(f"amplitude_n={amplitude!r} must be > 0 N")
    mu = np.ones_like(frequency) if weights is None else _vector("weights", weights)
    if mu.size != frequency.size:
        raise IdentificationError(
            f"weights has {mu.size} values but frequency_hz has {frequency.size}: "
            "lengths must match"
        )
    negative = np.flatnonzero(mu < 0.0)
    if negative.size:
        index = int(negative[0])
        raise IdentificationError(f"weights[{index}] = {float(mu[index])!r} must be >= 0")
    if not np.any(mu > 0.0):
        raise IdentificationError("weights are all zero: no data point counts")
    return _Data(frequency, speed, mu, amplitude)


def distinct_frequencies(frequency_hz: ArrayLike) -> tuple[F64, NDArray[np.intp]]:
    """The distinct frequencies, ascending (those within ``FREQUENCY_RESOLUTION_HZ`` of each
    other on its grid are one, represented by its first point), and each point's index into
    them."""
    f = np.asarray(frequency_hz, dtype=np.float64)
    keys = np.round(f / FREQUENCY_RESOLUTION_HZ)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return f[first], inverse.reshape(f.shape)


def _require_enough_frequencies(data: _Data, zeros: int, poles: int) -> None:
    used = data.weights > 0.0
    distinct, _ = distinct_frequencies(data.frequency_hz[used])
    if distinct.size == 1:
        raise IdentificationError(
            f"only one distinct frequency ({distinct[0]:g} Hz; frequencies closer than "
            f"{FREQUENCY_RESOLUTION_HZ:g} Hz count as one): a frequency response needs several"
        )
    parameters = zeros + poles + 1
    if distinct.size < parameters + 1:
        raise IdentificationError(
            f"order ({zeros} zeros, {poles} poles) has {parameters} free parameters (gain, zeros, "
            f"poles) and needs >= {parameters + 1} distinct frequencies; got {distinct.size}"
        )
    speeds = data.speed_mps[used]
    if np.all(speeds == speeds[0]):
        raise IdentificationError(
            f"every measured speed equals {float(speeds[0])!r} m/s: "
            "there is no response to identify"
        )


def fit_rational(
    frequency_hz: ArrayLike,
    speed_mps: ArrayLike,
    amplitude_n: float,
    zeros: int,
    poles: int,
    weights: ArrayLike | None = None,
    *,
    min_bandwidth_hz: float | None = None,
    starts: int = 8,
    seed: int = 0,
) -> FitResult:
    """Fit G(s) with ``zeros`` zeros and ``poles`` poles to a speed sweep (Eqs. 22-23).

    Minimises ``sum_k mu_k (v_k - |G(j 2 pi f_k)| A)^2`` (``mu_k = weights``, default 1; finite,
    >= 0, not all zero) over stable poles and minimum-phase zeros: a magnitude fit cannot tell in
    which half-plane a zero lies, and reports the left-half-plane one. Negative speeds (the part
    running backwards) are accepted, but |G| >= 0 cannot follow them: they just fit badly.
    Repeated frequencies are fine (e.g. three runs per setting); at least ``zeros + poles + 2``
    distinct ones (with weight > 0) are needed.

    Resolution: a resonance or notch narrower than the frequency step cannot be resolved by the
    sweep, and a fit that may place one between two samples uses it to chase noise. Each pair of
    poles or zeros therefore keeps its bandwidth ``2 zeta w_n = -2 Re p`` (rad/s) at or above
    ``2 pi min_bandwidth_hz``; default: the median step between the distinct frequencies; 0
    lifts the limit. Real roots are not limited.

    Starts: the Levy/Sanathanan-Koerner estimate plus ``starts`` random ones (``seed``:
    deterministic); each is refined by ``least_squares`` (Levenberg-Marquardt, analytic
    Jacobian) and the lowest cost wins.
    """
    zeros, poles = _order(zeros, poles)
    if isinstance(starts, bool) or not isinstance(starts, int) or starts < 0:
        raise IdentificationError(f"starts={starts!r} must be an integer >= 0")
    data = _checked_data(frequency_hz, speed_mps, amplitude_n, weights)
    _require_enough_frequencies(data, zeros, poles)
    used = data.weights > 0.0
    f_used = data.frequency_hz[used]
    f_ref = math.sqrt(float(f_used.min()) * float(f_used.max()))
    bandwidth = _resolution_hz(f_used) if min_bandwidth_hz is None else min_bandwidth_hz
    bandwidth = _real("min_bandwidth_hz", bandwidth)
    if bandwidth < 0.0:
        raise IdentificationError(f"min_bandwidth_hz={bandwidth!r} must be >= 0")
    layout = _Layout(zeros, poles, floor=bandwidth / f_ref)
    speed_scale = float(np.sqrt(np.mean(data.speed_mps[used] ** 2))) / data.amplitude_n
    x = (data.frequency_hz[used] / f_ref) ** 2
    y = data.speed_mps[used] / (data.amplitude_n * speed_scale)
    sqrt_mu = np.sqrt(data.weights[used])
    theta = _best_refinement(layout, x, y, sqrt_mu, starts, seed)
    model = _model_from_theta(layout, theta, 2.0 * math.pi * f_ref, speed_scale)
    predicted = model.magnitude(f_used) * data.amplitude_n
    measured = data.speed_mps[used]
    return FitResult(
        model=model,
        zeros=zeros,
        poles=poles,
        frequency_hz=_frozen(data.frequency_hz),
        measured_speed_mps=_frozen(data.speed_mps),
        amplitude_n=data.amplitude_n,
        fit_percent=fit_percent(measured, predicted),
        residual_rms_mps=float(np.sqrt(np.mean((measured - predicted) ** 2))),
    )


def _resolution_hz(frequency_hz: F64) -> float:
    """The median step between the sorted distinct frequencies."""
    return float(np.median(np.diff(distinct_frequencies(frequency_hz)[0])))


def _frozen(array: F64) -> F64:
    copy = np.array(array, dtype=np.float64)
    copy.setflags(write=False)
    return copy


def _best_refinement(layout: _Layout, x: F64, y: F64, sqrt_mu: F64, starts: int, seed: int) -> F64:
    """The lowest-cost least-squares refinement over all starting points.

    Two stages: every start gets a short budget of evaluations, then the two best are refined
    to convergence; the lowest final cost wins (ties: the earlier start, so the result is
    deterministic for a given seed).
    """
    rng = np.random.default_rng(seed)
    candidates: list[F64] = []
    levy = _levy_start(layout, x, y, sqrt_mu)
    if levy is not None:
        candidates.append(levy)
    candidates += [_random_start(layout, x, rng) for _ in range(starts)]
    if not candidates:  # no random starts asked for and the linear estimate broke down
        candidates.append(_random_start(layout, x, rng))
    objective = _Objective(layout, x, y, sqrt_mu)
    exact = 1e-24 * float(np.sum(sqrt_mu**2 * y**2))  # cost at round-off level: nothing to gain
    explored: list[tuple[F64, float, bool]] = []
    for start in candidates:
        explored.append(objective.refine(start, 10 * layout.size + 30))
        if explored[-1][1] <= exact:
            break
    explored.sort(key=lambda result: result[1])
    final = [
        (theta, cost) if converged else objective.refine(theta, 200 * layout.size)[:2]
        for theta, cost, converged in explored[:2]
    ]
    return min(final, key=lambda result: result[1])[0]


class _Objective:
    """Eq. 23 for magnitudes in normalised units: r_k = sqrt(mu_k) (y_k - |G'(j w'_k)|)."""

    def __init__(self, layout: _Layout, x: F64, y: F64, sqrt_mu: F64) -> None:
        self.layout, self.x, self.y, self.sqrt_mu = layout, x, y, sqrt_mu
        gain_bound = 2.0 * _LOG_BOUND * (layout.zeros + layout.poles) + 50.0
        self.lower = np.full(layout.size, -_LOG_BOUND)
        self.upper = np.full(layout.size, _LOG_BOUND)
        self.lower[0], self.upper[0] = -gain_bound, gain_bound
        self._cache: tuple[bytes, F64, F64] | None = None

    def _evaluate(self, theta: F64) -> tuple[F64, F64]:
        """|G'| and d|G'|/dtheta, cached for the last theta (residuals and Jacobian share it)."""
        key = theta.tobytes()
        if self._cache is None or self._cache[0] != key:
            log_g, gradient = _log_magnitude(self.layout, theta, self.x)
            magnitude = np.exp(np.minimum(log_g, 700.0))
            self._cache = (key, magnitude, magnitude[:, np.newaxis] * gradient)
        return self._cache[1], self._cache[2]

    def residuals(self, theta: F64) -> F64:
        magnitude, _ = self._evaluate(theta)
        return np.asarray(self.sqrt_mu * (self.y - magnitude), dtype=np.float64)

    def jacobian(self, theta: F64) -> F64:
        _, derivative = self._evaluate(theta)
        return np.asarray(-self.sqrt_mu[:, np.newaxis] * derivative, dtype=np.float64)

    def with_optimal_gain(self, theta: F64) -> F64:
        """theta with the gain that is optimal for its shape (linear least squares in g)."""
        result = np.clip(theta, self.lower + 1e-6, self.upper - 1e-6)
        log_g, _ = _log_magnitude(self.layout, result, self.x)
        shape = np.exp(np.minimum(log_g - result[0], 700.0))
        mu = self.sqrt_mu**2
        gain = float(np.sum(mu * shape * self.y) / np.sum(mu * shape * shape))
        if gain > 0.0 and math.isfinite(gain):
            result[0] = float(np.clip(math.log(gain), self.lower[0] + 1e-6, self.upper[0] - 1e-6))
        return result

    def refine(self, start: F64, max_nfev: int) -> tuple[F64, float, bool]:
        """Levenberg-Marquardt (MINPACK, analytic Jacobian) from ``start``: (theta, cost, whether
        it converged). theta is clipped to the bounds inside the objective (flat beyond them), so
        a parameter drifting along a direction the data do not determine cannot overflow."""
        theta0 = self.with_optimal_gain(start)

        def residuals(theta: F64) -> F64:
            return self.residuals(np.clip(theta, self.lower, self.upper))

        def jacobian(theta: F64) -> F64:
            result = self.jacobian(np.clip(theta, self.lower, self.upper)).copy()
            result[:, (theta < self.lower) | (theta > self.upper)] = 0.0
            return result

        try:
            solution = least_squares(
                residuals,
                theta0,
                jac=jacobian,
                method="lm",
                x_scale="jac",
                xtol=1e-10,
                ftol=1e-10,
                gtol=1e-10,
                max_nfev=max_nfev,
            )
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            return theta0, math.inf, True
        cost = float(solution.cost) if math.isfinite(solution.cost) else math.inf
        theta = np.clip(np.asarray(solution.x, dtype=np.float64), self.lower, self.upper)
        return theta, cost, bool(solution.status > 0)


# --------------------------------------------------------------------------- model order


@dataclass(frozen=True, eq=False)
class OrderScore:
    """One candidate order: its fit on all data and on held-out frequencies (see compare_orders)."""

    zeros: int
    poles: int
    parameters: int
    fit_percent: float
    holdout_fit_percent: float
    fit: FitResult


def _fold_of_each_point(frequency_hz: F64, folds: int, block: int) -> NDArray[np.int64]:
    """Fold of each point: the sorted distinct frequencies in runs of ``block`` neighbours, runs
    dealt to the folds in turn ((rank // block) % folds). Repeats of one frequency share a fold,
    so a held-out frequency is never also seen in training."""
    distinct, inverse = distinct_frequencies(frequency_hz)
    rank = np.arange(distinct.size)[inverse]
    return np.asarray((rank // block) % folds, dtype=np.int64)


def min_distinct_frequencies(zeros: int, poles: int, folds: int = 5, block: int = 2) -> int:
    """Fewest distinct frequencies with which :func:`compare_orders` can score this order: every
    hold-out training set (and the whole sweep) must keep ``zeros + poles + 2`` of them."""
    zeros, poles = _order(zeros, poles)
    needed = zeros + poles + 2
    count = needed
    while True:
        fold = (np.arange(count) // max(block, 1)) % max(folds, 2)
        if count - int(np.bincount(fold).max()) >= needed:
            return count
        count += 1


def compare_orders(
    frequency_hz: ArrayLike,
    speed_mps: ArrayLike,
    amplitude_n: float,
    orders: Sequence[tuple[int, int]],
    weights: ArrayLike | None = None,
    *,
    folds: int = 5,
    block: int = 2,
    min_bandwidth_hz: float | None = None,
    starts: int = 8,
    seed: int = 0,
) -> list[OrderScore]:
    """Fit every (zeros, poles) order and score it on all data and on held-out frequencies.

    Hold-out scheme (K-fold over frequency, K = ``folds``, in interleaved runs of ``block``
    neighbours): the distinct frequencies (with weight > 0) are sorted, cut into runs of
    ``block`` adjacent ones, and the runs are dealt to the folds in turn (run r to fold r % K),
    so every fold samples the whole band. Each fold is predicted by a model fitted, with the same
    settings, to the other K - 1 folds; ``holdout_fit_percent`` is :func:`fit_percent` of all
    these out-of-fold predictions against the measurements. Holding out neighbours in pairs
    (default) matters: with single frequencies held out, a high order that bends to a chance
    run of two or three noisy points is rewarded when it predicts one of them from the others;
    with the run held out together it is not. ``min_bandwidth_hz`` (see :func:`fit_rational`;
    default the median step of all the data) is the same for every fit. Every order must leave
    enough distinct frequencies in each training set (IdentificationError otherwise). The
    result is in the order of ``orders``.
    """
    data = _checked_data(frequency_hz, speed_mps, amplitude_n, weights)
    for name, value, least in (("folds", folds, 2), ("block", block, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise IdentificationError(f"{name}={value!r} must be an integer >= {least}")
    if not orders:
        raise IdentificationError("orders is empty: nothing to compare")
    checked = [_order(z, p) for z, p in orders]
    used = data.weights > 0.0
    distinct = distinct_frequencies(data.frequency_hz[used])[0].size
    for zeros, poles in checked:
        _require_enough_frequencies(data, zeros, poles)
        needed = min_distinct_frequencies(zeros, poles, folds, block)
        if distinct < needed:
            raise IdentificationError(
                f"order ({zeros} zeros, {poles} poles) needs >= {needed} distinct frequencies "
                f"for the hold-out check (folds={folds}, block={block}); got {distinct}"
            )
    if min_bandwidth_hz is None:
        min_bandwidth_hz = _resolution_hz(data.frequency_hz[used])
    settings = _FitSettings(min_bandwidth_hz, starts, seed)
    fold = _fold_of_each_point(data.frequency_hz[used], folds, block)
    return [_score_order(data, zeros, poles, fold, settings) for zeros, poles in checked]


@dataclass(frozen=True)
class _FitSettings:
    min_bandwidth_hz: float
    starts: int
    seed: int

    def fit(self, data: _Data, zeros: int, poles: int) -> FitResult:
        return fit_rational(
            data.frequency_hz,
            data.speed_mps,
            data.amplitude_n,
            zeros,
            poles,
            data.weights,
            min_bandwidth_hz=self.min_bandwidth_hz,
            starts=self.starts,
            seed=self.seed,
        )


def _score_order(
    data: _Data, zeros: int, poles: int, fold: NDArray[np.int64], settings: _FitSettings
) -> OrderScore:
    full = settings.fit(data, zeros, poles)
    used = data.weights > 0.0
    frequency, speed, mu = data.frequency_hz[used], data.speed_mps[used], data.weights[used]
    predicted = np.zeros_like(speed)
    folds = int(fold.max()) + 1
    for k in range(folds):
        held_out = fold == k
        training = _Data(frequency[~held_out], speed[~held_out], mu[~held_out], data.amplitude_n)
        try:
            part = settings.fit(training, zeros, poles)
        except IdentificationError as exc:
            raise IdentificationError(
                f"order ({zeros} zeros, {poles} poles), hold-out fold {k + 1} of {folds}: {exc}"
            ) from None
        predicted[held_out] = part.model.magnitude(frequency[held_out]) * data.amplitude_n
    return OrderScore(
        zeros=zeros,
        poles=poles,
        parameters=zeros + poles + 1,
        fit_percent=full.fit_percent,
        holdout_fit_percent=fit_percent(speed, predicted),
        fit=full,
    )


def best_order(scores: Sequence[OrderScore], tolerance_percent: float = 1.0) -> OrderScore:
    """The best order by hold-out fit; ties go to fewer parameters.

    Scores within ``tolerance_percent`` (percentage points) of the best hold-out fit count as
    tied: differences that small are at the noise level of the hold-out estimate, and the
    simpler model is the safer one. Among tied scores: fewest parameters, then the best hold-out
    fit, then the first given.
    """
    if not scores:
        raise IdentificationError("no order scores to choose from")
    tolerance = _real("tolerance_percent", tolerance_percent)
    if tolerance < 0.0:
        raise IdentificationError(f"tolerance_percent={tolerance!r} must be >= 0")
    top = max(score.holdout_fit_percent for score in scores)
    tied = [score for score in scores if score.holdout_fit_percent >= top - tolerance]
    return min(tied, key=lambda score: (score.parameters, -score.holdout_fit_percent))
