"""The paper's simplified travel estimate (Eqs. 17/18) and its stick-slip conditions (set S).

Both are kept beside the full hybrid simulation, not instead of it.

**Eqs. 17/18, "pure drag forward, pure slip backward".** Cut the run at the roots of the carrier
velocity, ``t_0 < t_1 < ... < t_n`` (``t_0`` the start, ``t_n`` the end). In an interval where the
carrier moves forward the part is assumed glued to it (drag) and travels the carrier's displacement
``v(t_{k+1}) - v(t_k)``; in an interval where the carrier moves backward the part is assumed to slip
the whole time from the carrier's velocity at ``t_k`` (zero at a root) with the constant
kinetic-friction acceleration, so it travels ``v'(t_k)*dt - mu_d*g*kappa*dt**2/2``, ``dt = t_{k+1} -
t_k``. The paper prints the slip term with a plus sign inside a sum that also adds the carrier
displacement, and writes the total as ``||dv_f|| - ||dv_s||``: the reading here is the one
consistent with that total and with Coulomb friction (a part that slips while the carrier moves back
is pulled back). ``sin(∅)`` is read as the friction multiplier ``kappa`` (MODEL-NOTES).

Where it differs from the full model: the estimate ignores Eq. 11 entirely. A part that the full
model keeps stuck in a backward stroke (small amplitude, e.g. A = 0.4 N) is charged a slip of
``mu_d*g*kappa*dt**2/2`` per stroke, so the estimate predicts fast forward travel where the full
model predicts none; and a part slipping backward from rest always catches up with the carrier
before the stroke ends (the carrier is at rest again, the part is not), after which the full model
re-sticks or slips the other way. The estimate agrees with the full model exactly on the pieces
where its assumptions hold: forward strokes in which the part sticks throughout, and the part of a
backward stroke between a slip onset at the velocity root and the first event after it.

**Set S (Section 4).** Necessary conditions for forward travel: while the carrier moves forward its
acceleration stays below the stick limit ``mu_s*g*kappa`` (the part is dragged), and while it moves
backward its acceleration exceeds that limit (the part slips). :func:`stick_slip_conditions` reports
the margins to the threshold, in m/s^2, for a sampled carrier trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from feeder_ros.physics.parameters import FeederParameters, ParameterError, finite_number

__all__ = [
    "SimplifiedEstimate",
    "StickSlipConditions",
    "carrier_velocity_roots",
    "simplified_estimate",
    "stick_slip_conditions",
]

FloatArray = NDArray[np.float64]


def _samples(**named: FloatArray) -> tuple[FloatArray, ...]:
    """The named sample arrays as 1-D float64 arrays of one length; ParameterError naming the
    array and the first bad sample otherwise (a NaN would turn every estimate into noise)."""
    arrays = tuple(np.asarray(arr, dtype=np.float64) for arr in named.values())
    shapes = {name: arr.shape for name, arr in zip(named, arrays, strict=True)}
    if any(arr.ndim != 1 for arr in arrays) or len(set(shapes.values())) != 1:
        described = ", ".join(f"{name} {shape}" for name, shape in shapes.items())
        raise ParameterError(f"sample arrays must be 1-D of one length, got {described}")
    for name, arr in zip(named, arrays, strict=True):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise ParameterError(
                f"{name}[{bad[0]}]={float(arr[bad[0]])!r} is not finite ({bad.size} such sample(s))"
            )
    return arrays


def _ascending(t: FloatArray) -> None:
    back = np.flatnonzero(np.diff(t) <= 0.0)
    if back.size:
        k = int(back[0])
        raise ParameterError(
            f"sample times must be strictly ascending: t[{k + 1}]={float(t[k + 1])!r} after "
            f"t[{k}]={float(t[k])!r}"
        )


def _hermite(
    t0: FloatArray, t1: FloatArray, y0: FloatArray, y1: FloatArray,
    d0: FloatArray, d1: FloatArray, t: FloatArray,
) -> FloatArray:  # fmt: skip
    """Cubic Hermite interpolant through (t0, y0, d0) and (t1, y1, d1), evaluated at t."""
    h = t1 - t0
    s = (t - t0) / h
    h00 = (1 + 2 * s) * (1 - s) ** 2
    h10 = s * (1 - s) ** 2
    h01 = s * s * (3 - 2 * s)
    h11 = s * s * (s - 1)
    return np.asarray(h00 * y0 + h10 * h * d0 + h01 * y1 + h11 * h * d1)


def carrier_velocity_roots(
    t: FloatArray, x: FloatArray, v: FloatArray, a: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Times and displacements where the sampled carrier velocity changes sign.

    Each root is located on the cubic Hermite interpolant of ``v`` (with derivative ``a``) between
    the two samples that bracket it (bisection to round-off), and ``x`` there on the Hermite
    interpolant of ``x`` (derivative ``v``). Samples with ``v == 0`` exactly count as roots too (the
    start from rest does not: it is ``t_0``).
    """
    t, x, v, a = _samples(t=t, x=x, v=v, a=a)
    _ascending(t)
    sign = np.sign(v)
    # carry the last non-zero sign over exact zeros so that a touch-and-return is not a root
    nonzero = np.flatnonzero(sign != 0)
    if nonzero.size < 2:
        return np.zeros(0), np.zeros(0)
    s = sign[nonzero]
    change = np.flatnonzero(s[1:] != s[:-1])
    left = nonzero[change]
    right = nonzero[change + 1]
    t0, t1 = t[left], t[right]
    lo, hi = t0.copy(), t1.copy()
    v_lo = v[left]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        v_mid = _hermite(t0, t1, v[left], v[right], a[left], a[right], mid)
        same = np.sign(v_mid) == np.sign(v_lo)
        lo = np.where(same, mid, lo)
        hi = np.where(same, hi, mid)
    roots = 0.5 * (lo + hi)
    x_roots = _hermite(t0, t1, x[left], x[right], v[left], v[right], roots)
    return roots, x_roots


@dataclass(frozen=True)
class SimplifiedEstimate:
    """Eq. 18 cut into the carrier's strokes: one entry per interval between velocity roots."""

    start_t_s: FloatArray
    end_t_s: FloatArray
    forward: NDArray[np.bool_]  # carrier moving forward in the interval (drag) or backward (slip)
    displacement_m: FloatArray  # the part's estimated travel in the interval

    @property
    def total_displacement_m(self) -> float:
        return float(self.displacement_m.sum())

    @property
    def drag_m(self) -> float:
        """Sum of the forward (drag) strokes, ``||dv_f||`` summed."""
        return float(self.displacement_m[self.forward].sum())

    @property
    def slip_m(self) -> float:
        """Sum of the backward (slip) strokes, ``-||dv_s||`` summed (negative or zero)."""
        return float(self.displacement_m[~self.forward].sum())

    @property
    def mean_speed_mps(self) -> float:
        span = float(self.end_t_s[-1] - self.start_t_s[0]) if self.end_t_s.size else 0.0
        return self.total_displacement_m / span if span > 0.0 else 0.0


def simplified_estimate(
    params: FeederParameters,
    t: FloatArray,
    x: FloatArray,
    v: FloatArray,
    a: FloatArray,
    kinetic_friction: float | None = None,
) -> SimplifiedEstimate:
    """Eq. 18 for a sampled carrier trajectory (``t`` ascending; ``x``, ``v``, ``a`` SI).

    ``kinetic_friction`` defaults to ``params.kinetic_friction``. Non-finite samples, times not
    strictly ascending, arrays of different lengths and a negative or non-finite friction raise
    :class:`~feeder_ros.physics.parameters.ParameterError` (a ValueError) naming the value.
    """
    t, x, v, a = _samples(t=t, x=x, v=v, a=a)
    if t.size < 2:
        raise ParameterError(f"at least 2 samples are needed, got {t.size}")
    mu_d = (
        params.kinetic_friction
        if kinetic_friction is None
        else finite_number("kinetic_friction", kinetic_friction, nonnegative=True)
    )
    slip_acc = mu_d * params.gravity_mps2 * params.friction_multiplier
    roots, x_roots = carrier_velocity_roots(t, x, v, a)
    bounds_t = np.concatenate([[t[0]], roots, [t[-1]]])
    bounds_x = np.concatenate([[x[0]], x_roots, [x[-1]]])
    bounds_v = np.concatenate([[v[0]], np.zeros(roots.size), [v[-1]]])
    start, end = bounds_t[:-1], bounds_t[1:]
    dt = end - start
    # direction of each interval: the carrier velocity at its midpoint (nearest sample)
    mid = np.clip(np.searchsorted(t, 0.5 * (start + end)), 0, t.size - 1)
    direction = np.sign(v[mid])
    direction = np.where(direction == 0, np.sign(bounds_x[1:] - bounds_x[:-1]), direction)
    forward = direction >= 0
    drag = bounds_x[1:] - bounds_x[:-1]
    slip = bounds_v[:-1] * dt - 0.5 * slip_acc * dt * dt
    keep = dt > 0
    return SimplifiedEstimate(
        start_t_s=start[keep],
        end_t_s=end[keep],
        forward=forward[keep],
        displacement_m=np.where(forward, drag, slip)[keep],
    )


@dataclass(frozen=True)
class StickSlipConditions:
    """The set S of Section 4 for a carrier trajectory, as margins to the stick limit (m/s^2)."""

    stick_limit_mps2: float  # mu_s*g*kappa
    forward_peak_mps2: float  # largest |a| while the carrier moves forward
    backward_peak_mps2: float  # largest |a| while the carrier moves backward

    @property
    def forward_margin_mps2(self) -> float:
        """> 0: a part is never shaken loose during forward strokes (pure drag is possible)."""
        return self.stick_limit_mps2 - self.forward_peak_mps2

    @property
    def backward_margin_mps2(self) -> float:
        """> 0: the backward strokes exceed the stick limit somewhere (the part slips back)."""
        return self.backward_peak_mps2 - self.stick_limit_mps2

    @property
    def holds(self) -> bool:
        """Both conditions of S: necessary (not sufficient) for forward travel."""
        return self.forward_margin_mps2 > 0.0 and self.backward_margin_mps2 > 0.0


def stick_slip_conditions(
    params: FeederParameters, v: FloatArray, a: FloatArray, static_friction: float | None = None
) -> StickSlipConditions:
    """Set S for sampled carrier velocity ``v`` and acceleration ``a`` (non-finite samples and a
    negative or non-finite friction raise ParameterError naming the value)."""
    v, a = _samples(v=v, a=a)
    a = np.abs(a)
    mu_s = (
        params.static_friction
        if static_friction is None
        else finite_number("static_friction", static_friction, nonnegative=True)
    )
    limit = mu_s * params.gravity_mps2 * params.friction_multiplier
    forward = a[v > 0]
    backward = a[v < 0]
    return StickSlipConditions(
        stick_limit_mps2=limit,
        forward_peak_mps2=float(forward.max()) if forward.size else 0.0,
        backward_peak_mps2=float(backward.max()) if backward.size else 0.0,
    )
