"""Coulomb stick-slip model of one nominal part driven by a sampled carrier (paper Eqs. 11-16).

The observer is the part model of the simulator run on an *estimated* carrier: given carrier
velocity and acceleration samples ``(t_k, v_k, a_k)`` it propagates the part's lab-frame velocity
``u`` and its phase, event-accurately within each sample interval:

* Between two samples the carrier velocity is the cubic Hermite interpolant of ``(v, a)`` at both
  ends, so the acceleration (its derivative, a quadratic) is consistent with the velocity.
* STICK: ``u = v``; the part starts to slip at the first instant where ``|a| = L = mu_s*g*kappa``,
  a root of a quadratic: backward (``a > L``: the part lags, ``u' = +D``) or forward
  (``a < -L``: the part runs ahead, ``u' = -D``), ``D = mu_d*g*kappa``.
* SLIP: ``u`` is linear in time; the relative velocity ``v - u`` is a cubic whose first zero
  (located by splitting at its extrema and bisecting a bracketed monotone piece) ends the slip: the
  part sticks if ``|a| <= L`` there, otherwise it slips the other way.

Any number of events per interval are handled. Per interval the kernel also returns the part's
displacement (exact integral of ``u``) and the time spent slipping, from which the estimator forms
mean speed, advance per cycle and slip fraction. Phase codes are those of
``msg/VehicleEstimate.msg`` and of :class:`feeder_ros.physics.simulation.Phase`; a sample at an
event instant shows the state just after the event, as in the simulator.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from feeder_ros.physics.parameters import FeederParameters, ParameterError

__all__ = [
    "PHASE_SLIP_BACKWARD",
    "PHASE_SLIP_FORWARD",
    "PHASE_STICK",
    "ObserverOutput",
    "PartModel",
    "StickSlipObserver",
]

F64 = npt.NDArray[np.float64]
I8 = npt.NDArray[np.int8]

PHASE_STICK = 0
PHASE_SLIP_FORWARD = 1  # part faster than the carrier (u > v)
PHASE_SLIP_BACKWARD = 2  # part slower than the carrier (u < v)

# state vector of the kernel
_S_T = 0  # time of the last processed sample
_S_V = 1  # carrier velocity there
_S_A = 2  # carrier acceleration there
_S_U = 3  # part velocity there
_S_PHASE = 4
_S_VALID = 5  # 1 once a first sample has been seen
_STATE_SIZE = 6
_MAX_EVENTS_PER_INTERVAL = 64


@dataclass(frozen=True)
class PartModel:
    """Friction of the nominal part: ``mu_s``, ``mu_d``, groove multiplier ``kappa`` and ``g``."""

    static_friction: float = 0.2
    kinetic_friction: float = 0.1
    friction_multiplier: float = 1.0
    gravity_mps2: float = 9.81

    def __post_init__(self) -> None:
        for name in ("static_friction", "kinetic_friction", "friction_multiplier", "gravity_mps2"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ParameterError(f"{name}={value!r} is not a number")
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError(f"{name}={value!r} must be finite and > 0")
            object.__setattr__(self, name, float(value))
        if self.kinetic_friction > self.static_friction:
            raise ParameterError(
                f"kinetic_friction={self.kinetic_friction!r} must not exceed "
                f"static_friction={self.static_friction!r}"
            )

    @classmethod
    def from_parameters(cls, params: FeederParameters) -> PartModel:
        return cls(
            params.static_friction,
            params.kinetic_friction,
            params.friction_multiplier,
            params.gravity_mps2,
        )

    @property
    def stick_limit_mps2(self) -> float:
        """L = mu_s*g*kappa (Eq. 11)."""
        return self.static_friction * self.gravity_mps2 * self.friction_multiplier

    @property
    def slip_deceleration_mps2(self) -> float:
        """D = mu_d*g*kappa."""
        return self.kinetic_friction * self.gravity_mps2 * self.friction_multiplier


@dataclass(frozen=True)
class ObserverOutput:
    """Per input sample: part velocity ``part_v_mps``, ``phase``; per interval ending at the sample:
    part displacement ``part_dx_m`` and slip time ``slip_s`` (0 for the very first sample)."""

    part_v_mps: F64
    phase: I8
    part_dx_m: F64
    slip_s: F64


# -- kernel ------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _cubic(v0, a0, c2, c3, tau):
    return v0 + tau * (a0 + tau * (c2 + tau * c3))


@njit(cache=True, inline="always")
def _quad(a0, c2, c3, tau):
    return a0 + tau * (2.0 * c2 + 3.0 * c3 * tau)


@njit(cache=True, inline="always")
def _integral(v0, a0, c2, c3, tau):
    return tau * (v0 + tau * (0.5 * a0 + tau * (c2 / 3.0 + 0.25 * c3 * tau)))


@njit(cache=True)
def _quadratic_roots(qa, qb, qc, lo, hi, out):
    """Real roots of qa*x^2 + qb*x + qc in (lo, hi], sorted, into out; returns their count."""
    n = 0
    scale = abs(qa) * (hi - lo) ** 2 + abs(qb) * (hi - lo) + abs(qc)
    if abs(qa) * (hi - lo) ** 2 <= 1e-14 * scale:
        if qb != 0.0:
            x = -qc / qb
            if lo < x <= hi:
                out[0] = x
                n = 1
        return n
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        return 0
    sq = math.sqrt(disc)
    q = -0.5 * (qb + math.copysign(sq, qb))
    x1 = q / qa
    x2 = qc / q if q != 0.0 else x1
    if x1 > x2:
        x1, x2 = x2, x1
    if lo < x1 <= hi:
        out[n] = x1
        n += 1
    if lo < x2 <= hi and x2 != x1:
        out[n] = x2
        n += 1
    return n


@njit(cache=True)
def _first_stick_exit(a0, c2, c3, L, s, h, roots):
    """First tau in (s, h] where |a(tau)| leaves [-L, L]; returns (tau, direction) or (inf, 0).

    ``a(s)`` already outside counts as an exit at ``s`` (direction by its sign)."""
    a_s = _quad(a0, c2, c3, s)
    if a_s > L:
        return s, PHASE_SLIP_BACKWARD
    if a_s < -L:
        return s, PHASE_SLIP_FORWARD
    best = math.inf
    direction = 0
    for sign in (1.0, -1.0):
        n = _quadratic_roots(3.0 * c3, 2.0 * c2, a0 - sign * L, s, h, roots)
        for i in range(n):
            r = roots[i]
            # an exit: the acceleration moves outward through the limit at r
            slope = 2.0 * c2 + 6.0 * c3 * r
            if sign * slope > 0.0 and r < best:
                best = r
                direction = PHASE_SLIP_BACKWARD if sign > 0.0 else PHASE_SLIP_FORWARD
            elif slope == 0.0 and r < best:
                # tangential touch: check just after
                eps = 1e-9 * (h - s)
                if sign * (_quad(a0, c2, c3, r + eps) - sign * L) > 0.0:
                    best = r
                    direction = PHASE_SLIP_BACKWARD if sign > 0.0 else PHASE_SLIP_FORWARD
    return best, direction


@njit(cache=True)
def _first_relative_zero(v0, a0, c2, c3, us, p, ts, sgn, s, h, roots, pts):
    """First tau in (s, h] where sgn*(v(tau) - u(tau)) <= 0, u = us + p*(tau - ts); inf if none."""
    # r'(tau) = a(tau) - p: split (s, h] at its zeros into monotone pieces
    n = _quadratic_roots(3.0 * c3, 2.0 * c2, a0 - p, s, h, roots)
    pts[0] = s
    m = 1
    for i in range(n):
        if roots[i] > pts[m - 1] and roots[i] < h:
            pts[m] = roots[i]
            m += 1
    pts[m] = h
    m += 1
    for i in range(1, m):
        lo, hi = pts[i - 1], pts[i]
        f_hi = sgn * (_cubic(v0, a0, c2, c3, hi) - us - p * (hi - ts))
        if f_hi > 0.0:
            continue
        f_lo = sgn * (_cubic(v0, a0, c2, c3, lo) - us - p * (lo - ts))
        if f_lo <= 0.0:
            if lo > s:
                return lo
            # starting at (or numerically just past) zero: the piece heads the wrong way only if
            # the relative velocity is already decreasing; take the start as the event
            slope = sgn * (_quad(a0, c2, c3, lo) - p)
            if slope <= 0.0 and f_lo < 0.0:
                return lo
            if slope <= 0.0 and hi > lo:
                return hi if f_hi == 0.0 else lo
            continue
        # bracketed: f(lo) > 0 >= f(hi), monotone piece
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            f_mid = sgn * (_cubic(v0, a0, c2, c3, mid) - us - p * (mid - ts))
            if f_mid > 0.0:
                lo = mid
            else:
                hi = mid
        return hi
    return math.inf


# nogil: the calibration's worker thread runs it while the node's executor publishes
@njit(cache=True, nogil=True)
def _observe(t, v, a, L, D, state, out_u, out_phase, out_dx, out_slip):
    """Propagate the part over the samples; ``state`` is updated in place. Returns a status:
    0 done, 1 too many events in an interval (the interval was finished without further events)."""
    status = 0
    roots = np.empty(2)
    roots2 = np.empty(2)
    pts = np.empty(4)
    start = 0
    if state[_S_VALID] == 0.0:
        if t.size == 0:
            return status
        state[_S_T] = t[0]
        state[_S_V] = v[0]
        state[_S_A] = a[0]
        state[_S_U] = v[0]
        phase0 = PHASE_STICK
        if a[0] > L:
            phase0 = PHASE_SLIP_BACKWARD
        elif a[0] < -L:
            phase0 = PHASE_SLIP_FORWARD
        state[_S_PHASE] = phase0
        state[_S_VALID] = 1.0
        out_u[0] = v[0]
        out_phase[0] = phase0
        out_dx[0] = 0.0
        out_slip[0] = 0.0
        start = 1
    for k in range(start, t.size):
        t0 = state[_S_T]
        h = t[k] - t0
        v0 = state[_S_V]
        a0 = state[_S_A]
        v1 = v[k]
        a1 = a[k]
        u = state[_S_U]
        phase = int(state[_S_PHASE])
        dx = 0.0
        slip = 0.0
        if h <= 0.0:
            out_u[k] = u
            out_phase[k] = phase
            out_dx[k] = 0.0
            out_slip[k] = 0.0
            continue
        dv = (v1 - v0) / h
        c2 = (3.0 * dv - 2.0 * a0 - a1) / h
        c3 = (a0 + a1 - 2.0 * dv) / (h * h)
        s = 0.0
        if phase == PHASE_STICK:
            u = v0  # stick: the part moves with the carrier
        ts = 0.0  # time of the last slip start (tau), for the linear u
        us = u
        events = 0
        while True:
            if phase == PHASE_STICK:
                tau, direction = _first_stick_exit(a0, c2, c3, L, s, h, roots)
                if tau > h or events >= _MAX_EVENTS_PER_INTERVAL:
                    dx += _integral(v0, a0, c2, c3, h) - _integral(v0, a0, c2, c3, s)
                    u = v1
                    if events >= _MAX_EVENTS_PER_INTERVAL:
                        status = 1
                    break
                dx += _integral(v0, a0, c2, c3, tau) - _integral(v0, a0, c2, c3, s)
                phase = direction
                us = _cubic(v0, a0, c2, c3, tau)
                ts = tau
                s = tau
                events += 1
            else:
                p = D if phase == PHASE_SLIP_BACKWARD else -D
                sgn = 1.0 if phase == PHASE_SLIP_BACKWARD else -1.0
                tau = _first_relative_zero(v0, a0, c2, c3, us, p, ts, sgn, s, h, roots2, pts)
                end = min(tau, h)
                # part displacement over [s, end]: u linear
                u_s = us + p * (s - ts)
                dx += (end - s) * (u_s + 0.5 * p * (end - s))
                slip += end - s
                if tau > h or events >= _MAX_EVENTS_PER_INTERVAL:
                    u = us + p * (h - ts)
                    if events >= _MAX_EVENTS_PER_INTERVAL:
                        status = 1
                    break
                a_tau = _quad(a0, c2, c3, tau)
                us = _cubic(v0, a0, c2, c3, tau)
                ts = tau
                s = tau
                events += 1
                if abs(a_tau) <= L:
                    phase = PHASE_STICK
                else:
                    reverse = PHASE_SLIP_BACKWARD
                    if phase == PHASE_SLIP_BACKWARD:
                        reverse = PHASE_SLIP_FORWARD
                    phase = reverse
            if s >= h:
                u = v1 if phase == PHASE_STICK else us
                break
        state[_S_T] = t[k]
        state[_S_V] = v1
        state[_S_A] = a1
        state[_S_U] = u
        state[_S_PHASE] = phase
        out_u[k] = u
        out_phase[k] = phase
        out_dx[k] = dx
        out_slip[k] = slip
    return status


class StickSlipObserver:
    """Stateful stick-slip model of one nominal part (see the module docstring).

    ``StickSlipObserver(part)``; :meth:`update` consumes carrier samples in time order and returns
    the part's velocity and phase per sample. The first sample ever seen (or after :meth:`reset`)
    starts the part sticking to the carrier (or already slipping if ``|a| > L`` there).
    """

    def __init__(self, part: PartModel) -> None:
        self._part = part
        self._state = np.zeros(_STATE_SIZE)

    @property
    def part(self) -> PartModel:
        return self._part

    @property
    def started(self) -> bool:
        return bool(self._state[_S_VALID])

    @property
    def time_s(self) -> float:
        return float(self._state[_S_T]) if self.started else math.nan

    @property
    def part_velocity_mps(self) -> float:
        return float(self._state[_S_U]) if self.started else math.nan

    @property
    def phase(self) -> int:
        return int(self._state[_S_PHASE])

    def set_part(self, part: PartModel) -> None:
        """Run on with another part model (a calibrated one), keeping the part's state."""
        self._part = part

    def reset(self) -> None:
        """Forget the part's state; the next sample starts it again."""
        self._state[:] = 0.0

    def restart_interval(self, velocity_mps: float, acceleration_mps2: float) -> None:
        """Replace the carrier state at the last processed sample (a refitted carrier model),
        keeping
        the part's state; a sticking part keeps moving with the carrier."""
        if not self.started:
            return
        self._state[_S_V] = velocity_mps
        self._state[_S_A] = acceleration_mps2
        if int(self._state[_S_PHASE]) == PHASE_STICK:
            self._state[_S_U] = velocity_mps

    def update(
        self, t_s: npt.ArrayLike, carrier_v_mps: npt.ArrayLike, carrier_a_mps2: npt.ArrayLike
    ) -> ObserverOutput:
        """Propagate over the samples (strictly after the last processed time, increasing)."""
        t = np.ascontiguousarray(t_s, dtype=np.float64).ravel()
        v = np.ascontiguousarray(carrier_v_mps, dtype=np.float64).ravel()
        a = np.ascontiguousarray(carrier_a_mps2, dtype=np.float64).ravel()
        if not (t.shape == v.shape == a.shape):
            raise ValueError(f"sizes differ: t {t.size}, v {v.size}, a {a.size}")
        if t.size and self.started and t[0] <= self._state[_S_T]:
            raise ValueError(f"t_s[0]={t[0]!r} is not after the last sample {self._state[_S_T]!r}")
        if t.size > 1 and np.any(np.diff(t) <= 0.0):
            raise ValueError("t_s must be strictly increasing")
        n = t.size
        out_u, out_dx, out_slip = np.empty(n), np.empty(n), np.empty(n)
        out_phase = np.empty(n, np.int8)
        _observe(
            t,
            v,
            a,
            self._part.stick_limit_mps2,
            self._part.slip_deceleration_mps2,
            self._state,
            out_u,
            out_phase,
            out_dx,
            out_slip,
        )
        return ObserverOutput(out_u, out_phase, out_dx, out_slip)
