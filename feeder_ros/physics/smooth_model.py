"""The smooth (logistic) carrier model, Eq. 6 + Eq. 9, solved by :func:`scipy.integrate.solve_ivp`.

``M_eq*v'' + c*v' + K(s)*cos(theta)*v = F(t)`` with ``K(s) = K_b + (K_f - K_b)*expit(2*beta*s)``
(Eq. 9), ``s = v`` (switching on the displacement, Eq. 7) or ``s = v'`` (switching on the velocity,
Fig. 6). ``expit`` is evaluated in an overflow-safe form, so ``beta = 1e6`` (the case study) is
fine. This is the model the paper integrates with ode45; the project's default is the sharp switch
solved exactly (:mod:`feeder_ros.physics.simulation`), and this path exists for comparison and for
the benchmark.

Parts use the same Coulomb stick-slip model as the exact engine, driven one-way by the carrier: the
carrier is integrated first with dense output, then each part's events (stick -> slip when
``|a_carrier|`` exceeds ``mu_s*g*kappa``; slip -> stick or reversal when the relative velocity is
zero) are located by a bracketing scan of the solver's steps followed by a Brent root search on the
dense output. Between events a part is either glued to the carrier or moves with constant
acceleration ``±mu_d*g*kappa``, so its trajectory is exact given the carrier's.

Two-way coupling (Eq. 14) is not implemented on this path: it is refused.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import OdeSolution, solve_ivp
from scipy.optimize import brentq
from scipy.special import expit

from feeder_ros.physics.drive import DriveSchedule
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.results import EventKind, EventLog, PartSpec, Phase, SimulationResult

__all__ = [
    "LogisticCarrier",
    "PartTrack",
    "SolverOptions",
    "integrate_part",
    "logistic_stiffness",
    "simulate_smooth",
    "solve_logistic_carrier",
]

FloatArray = NDArray[np.float64]
ForceFunction = Callable[[FloatArray], FloatArray]
ScalarForce = Callable[[float], float]
SolverMethod = Literal["RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA"]

# Phase codes (feeder_ros.physics.results.Phase)
EXITED, STICK, SLIP_FORWARD, SLIP_BACKWARD = -1, 0, 1, 2


def logistic_stiffness(
    switch_value: FloatArray, k_forward: float, k_backward: float, beta: float
) -> FloatArray:
    """Eq. 9: ``K_b + (K_f - K_b)/(1 + exp(-2*beta*s))``, overflow-safe for any ``beta*s``."""
    return k_backward + (k_forward - k_backward) * expit(2.0 * beta * switch_value)


@dataclass(frozen=True)
class SolverOptions:
    """Choice of ``solve_ivp`` method and tolerances.

    ``atol=None`` picks a scale-aware absolute tolerance: ``rtol`` times the forward branch's static
    deflection ``A/(K_f*cos(theta))`` (and that times ``omega_f`` for the velocity), so the
    requested relative accuracy means something at A = 0.4 N, where the motion is about a
    micrometre. The paper's ode45 corresponds to ``SolverOptions.ode45_default()`` (``rtol=1e-3``,
    ``atol=1e-6``).
    """

    method: SolverMethod = "DOP853"
    rtol: float = 1e-9
    atol: float | None = None
    max_step: float = math.inf

    @classmethod
    def ode45_default(cls) -> SolverOptions:
        return cls(method="RK45", rtol=1e-3, atol=1e-6)

    def absolute_tolerance(self, params: FeederParameters) -> float | FloatArray:
        if self.atol is not None:
            return self.atol
        k_cos = params.forward_stiffness_n_per_m * params.cos_theta
        scale = max(params.drive_amplitude_n, 1e-6) / k_cos
        omega = math.sqrt(k_cos / params.equivalent_mass_kg)
        return np.array([self.rtol * scale, self.rtol * scale * omega])


def _attribute(obj: object, name: str) -> Any:
    """An attribute the type stubs do not declare (scipy's interpolant internals)."""
    return getattr(obj, name)


class _DenseTable:
    """Vectorised evaluation of ``solve_ivp``'s dense output over many steps at once.

    ``OdeSolution.__call__`` loops over steps in Python; for the explicit Runge-Kutta methods the
    interpolants are small polynomials (``RkDenseOutput``: ``y_old + h*Q @ [x, x^2, ...]``;
    ``Dop853DenseOutput``: a nested form in ``x`` and ``1 - x``), stacked here into arrays and
    evaluated together. Other methods fall back to ``OdeSolution``.
    """

    def __init__(self, pieces: Sequence[OdeSolution]) -> None:
        interpolants = [ip for piece in pieces for ip in piece.interpolants]
        names = {type(ip).__name__ for ip in interpolants}
        self.kind = ""
        if names == {"RkDenseOutput"}:  # RK23, RK45
            self.kind = "rk"
            self.table = np.stack([_attribute(ip, "Q") for ip in interpolants])  # (n, 2, order+1)
        elif names == {"Dop853DenseOutput"}:
            self.kind = "dop853"
            self.table = np.stack([_attribute(ip, "F") for ip in interpolants])  # (n, 7, 2)
        if self.kind:
            self.t_old = np.array([ip.t_old for ip in interpolants], dtype=np.float64)
            self.h = np.array([_attribute(ip, "h") for ip in interpolants], dtype=np.float64)
            self.y_old = np.stack([_attribute(ip, "y_old") for ip in interpolants])  # (n, 2)

    def __call__(self, t: FloatArray) -> FloatArray:
        """States (2, m) at the times ``t`` (m,)."""
        k = np.clip(np.searchsorted(self.t_old, t, side="right") - 1, 0, self.t_old.size - 1)
        h = self.h[k]
        x = (t - self.t_old[k]) / h
        if self.kind == "rk":
            q = self.table[k]  # (m, 2, order + 1)
            powers = np.cumprod(np.repeat(x[:, None], q.shape[2], axis=1), axis=1)
            y = h[:, None] * np.einsum("mij,mj->mi", q, powers) + self.y_old[k]
        else:
            f = self.table[k]  # (m, 7, 2)
            y = np.zeros((t.size, 2))
            xs = x[:, None]
            for i in range(f.shape[1]):
                y += f[:, f.shape[1] - 1 - i, :]
                y *= xs if i % 2 == 0 else 1.0 - xs
            y += self.y_old[k]
        return np.asarray(y.T, dtype=np.float64)


class LogisticCarrier:
    """Dense solution of the logistic carrier ODE: state and acceleration at any time in the run."""

    def __init__(
        self,
        params: FeederParameters,
        force: ForceFunction,
        duration_s: float,
        options: SolverOptions,
        breakpoints: Sequence[float] = (),
        scalar_force: ScalarForce | None = None,
    ) -> None:
        if params.coupling != "one_way":
            raise ValueError(
                f"coupling={params.coupling!r}: the logistic (Eq. 9) model implements one-way "
                "coupling only; use stiffness_model='sharp' for two-way coupling"
            )
        self.params = params
        self.force = force
        self._scalar_force = scalar_force or (lambda t: float(force(np.array([t]))[0]))
        self._mass = params.equivalent_mass_kg
        self._damping = params.damping_ns_per_m
        self._kf = params.forward_stiffness_n_per_m * params.cos_theta
        self._kb = params.backward_stiffness_n_per_m * params.cos_theta
        self._beta = params.logistic_beta_per_m
        self._on_velocity = params.stiffness_switch == "velocity"
        atol = options.absolute_tolerance(params)
        # integrate piecewise between drive breakpoints (where F or its derivatives jump)
        edges = sorted({0.0, duration_s, *(b for b in breakpoints if 0.0 < b < duration_s)})
        self._edges = np.array(edges)
        self._edge_list = edges
        self._pieces: list[OdeSolution] = []
        self.step_times: list[FloatArray] = []
        self.n_rhs = 0
        y0 = np.zeros(2)
        for start, stop in itertools.pairwise(edges):
            result = solve_ivp(
                self._rhs,
                (start, stop),
                y0,
                method=options.method,
                rtol=options.rtol,
                atol=atol,
                max_step=options.max_step,
                dense_output=True,
            )
            if not result.success or result.sol is None:
                raise RuntimeError("solve_ivp failed: " + str(result.message))
            self._pieces.append(result.sol)
            self.step_times.append(np.asarray(result.t, dtype=np.float64))
            self.n_rhs += int(result.nfev)
            y0 = result.y[:, -1].copy()
        self._table = _DenseTable(self._pieces)

    @property
    def n_steps(self) -> int:
        return sum(len(t) - 1 for t in self.step_times)

    def acceleration(self, t: FloatArray, x: FloatArray, v: FloatArray) -> FloatArray:
        """Eq. 6 solved for v'': (F - c*v' - K(s)*cos(theta)*v)/M_eq."""
        s = v if self._on_velocity else x
        k = logistic_stiffness(s, self._kf, self._kb, self._beta)
        return np.asarray((self.force(t) - self._damping * v - k * x) / self._mass)

    def _rhs(self, t: float, y: FloatArray) -> FloatArray:
        x, v = float(y[0]), float(y[1])
        z = 2.0 * self._beta * (v if self._on_velocity else x)
        # overflow-safe logistic 1/(1 + exp(-z))
        weight = 1.0 / (1.0 + math.exp(-z)) if z >= 0.0 else math.exp(z) / (1.0 + math.exp(z))
        k = self._kb + (self._kf - self._kb) * weight
        a = (self._scalar_force(t) - self._damping * v - k * x) / self._mass
        return np.array([v, a])

    def state_at(self, t: float) -> tuple[float, float, float]:
        """Displacement, velocity and acceleration at one time (fast path for root searches)."""
        piece = self._pieces[
            min(max(bisect.bisect_right(self._edge_list, t) - 1, 0), len(self._pieces) - 1)
        ]
        steps = piece.ts
        k = min(max(int(np.searchsorted(steps, t, side="right")) - 1, 0), len(steps) - 2)
        y = piece.interpolants[k](t)
        x, v = float(y[0]), float(y[1])
        return x, v, float(self._rhs(t, np.array([x, v]))[1])

    def state(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Carrier displacement, velocity and acceleration at the times ``t`` (within the run)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if self._table.kind:
            x, v = self._table(t)
            return x, v, self.acceleration(t, x, v)
        x = np.empty_like(t)
        v = np.empty_like(t)
        piece = np.clip(np.searchsorted(self._edges, t, side="right") - 1, 0, len(self._pieces) - 1)
        for index in np.unique(piece):
            mask = piece == index
            y = self._pieces[int(index)](t[mask])
            x[mask] = y[0]
            v[mask] = y[1]
        return x, v, self.acceleration(t, x, v)

    def branch(self, x: FloatArray, v: FloatArray) -> NDArray[np.int8]:
        """+1 where the switching variable is >= 0 (K closer to K_f), -1 elsewhere."""
        s = v if self._on_velocity else x
        return np.where(s >= 0.0, 1, -1).astype(np.int8)

    def scan_grid(self, subdivisions: int = 4) -> FloatArray:
        """Solver steps, each split into ``subdivisions`` parts: the bracketing grid for events."""
        grids = []
        for times in self.step_times:
            frac = np.arange(subdivisions) / subdivisions
            inner = times[:-1, None] + np.diff(times)[:, None] * frac[None, :]
            grids.append(inner.ravel())
        grids.append(np.array([self._edges[-1]]))
        return np.unique(np.concatenate(grids))


def solve_logistic_carrier(
    params: FeederParameters,
    duration_s: float,
    force: ForceFunction | None = None,
    options: SolverOptions | None = None,
    breakpoints: Sequence[float] = (),
    scalar_force: ScalarForce | None = None,
) -> LogisticCarrier:
    """Integrate the logistic carrier ODE from rest over ``[0, duration_s]``.

    ``force`` defaults to ``A*sin(2*pi*f_d*t)`` from ``params``.
    """
    if not (duration_s > 0.0 and math.isfinite(duration_s)):
        raise ValueError(f"duration_s={duration_s!r} must be positive and finite")
    if force is None:
        amplitude = params.drive_amplitude_n
        omega = 2.0 * math.pi * params.drive_frequency_hz

        def force(t: FloatArray) -> FloatArray:
            return np.asarray(amplitude * np.sin(omega * t))

        def scalar_force(t: float) -> float:
            return amplitude * math.sin(omega * t)

    return LogisticCarrier(
        params, force, duration_s, options or SolverOptions(), breakpoints, scalar_force
    )


@dataclass(frozen=True)
class PartTrack:
    """One part's piecewise trajectory: segment starts, phases and the state at each start."""

    start_t_s: FloatArray
    phase: NDArray[np.int8]
    x0_m: FloatArray  # lab position at the segment's start
    v0_mps: FloatArray
    offset_m: FloatArray  # part minus carrier displacement (track position) during STICK segments
    slip_acceleration_mps2: float
    end_t_s: float  # end of the run
    exit_t_s: float  # nan while on the track

    @property
    def slip_time_s(self) -> float:
        """Time spent slipping (up to the exit, if any)."""
        ends = np.append(self.start_t_s[1:], self.end_t_s)
        slipping = (self.phase == SLIP_FORWARD) | (self.phase == SLIP_BACKWARD)
        return float(np.sum((ends - self.start_t_s)[slipping]))

    def sample(
        self, t: FloatArray, carrier_x: FloatArray, carrier_v: FloatArray
    ) -> tuple[FloatArray, FloatArray, NDArray[np.int8]]:
        """Part position, velocity and phase at the times ``t`` (with the carrier's state there)."""
        seg = np.clip(np.searchsorted(self.start_t_s, t, side="right") - 1, 0, None)
        phase = self.phase[seg]
        dt = t - self.start_t_s[seg]
        # a part slipping backward relative to the carrier is dragged forward, and vice versa
        direction = np.where(phase == SLIP_BACKWARD, 1.0, -1.0)
        acc = direction * self.slip_acceleration_mps2
        slip_x = self.x0_m[seg] + self.v0_mps[seg] * dt + 0.5 * acc * dt * dt
        slip_v = self.v0_mps[seg] + acc * dt
        stuck = phase == STICK
        gone = phase == EXITED
        x = np.where(gone, np.nan, np.where(stuck, carrier_x + self.offset_m[seg], slip_x))
        v = np.where(gone, np.nan, np.where(stuck, carrier_v, slip_v))
        return x, v, phase.astype(np.int8)


_CHUNK = 512


def _first_root(
    func: Callable[[float], float], grid: FloatArray, values: FloatArray, index: int, t0: float
) -> tuple[float, int]:
    """First time after ``t0`` where ``func`` (> 0 just after ``t0``) reaches zero; its grid index.

    ``values`` are ``func`` on ``grid`` (vectorised); scanning starts at grid index ``index`` (the
    first grid point after ``t0``). Returns ``(inf, len(grid))`` if there is none.
    """
    while index < len(grid):
        stop = min(index + _CHUNK, len(grid))
        hits = np.flatnonzero(values[index:stop] <= 0.0)
        if hits.size:
            j = index + int(hits[0])
            right = float(grid[j])
            left = max(t0, float(grid[j - 1]))
            if left <= t0:  # the function may start at zero (just after its own event)
                left = t0 + 1e-9 * (right - t0)
            if func(left) <= 0.0:
                return 0.5 * (left + right), j  # shorter than the grid resolves
            return float(brentq(func, left, right, xtol=1e-15, rtol=4 * np.finfo(float).eps)), j
        index = stop
    return math.inf, len(grid)


@dataclass(frozen=True)
class _Grid:
    t: FloatArray
    x: FloatArray
    v: FloatArray
    a: FloatArray


def integrate_part(
    carrier: LogisticCarrier,
    grid: FloatArray,
    grid_a: FloatArray,
    grid_v: FloatArray,
    position_m: float,
    static_friction: float,
    kinetic_friction: float,
    grid_x: FloatArray | None = None,
) -> tuple[PartTrack, list[tuple[float, int, int]]]:
    """Events of one part riding on ``carrier`` (one-way), put on the track at ``position_m``.

    ``grid``/``grid_a``/``grid_v`` (and ``grid_x``) are the bracketing grid and the carrier's
    acceleration and velocity (and displacement) on it. A slipping part whose track position passes
    ``track_length_m`` leaves (``grid_x`` is needed for that; without it exits are not detected).
    Returns the track and the list of ``(time, phase_before, phase_after)`` transitions.
    """
    params = carrier.params
    kappa_g = params.gravity_mps2 * params.friction_multiplier
    limit = static_friction * kappa_g
    slip = kinetic_friction * kappa_g
    track = params.track_length_m
    end = float(grid[-1])

    carrier_at = carrier.state_at

    starts, phases = [0.0], [STICK]
    x0s, v0s, offsets = [position_m], [0.0], [position_m]
    transitions: list[tuple[float, int, int]] = []
    exit_t = math.nan

    t0, phase = 0.0, STICK
    part_x0, part_v0 = position_m, 0.0
    acc = 0.0
    index = 1  # first grid point strictly after t0
    while True:
        if phase == STICK:
            # first |a| > limit: positive margin L - sign*a for each sign, whichever comes first
            t_up, _ = _first_root(
                lambda t: limit - carrier_at(t)[2], grid, limit - grid_a, index, t0
            )
            t_dn, _ = _first_root(
                lambda t: limit + carrier_at(t)[2], grid, limit + grid_a, index, t0
            )
            found, kind = (t_up, "up") if t_up <= t_dn else (t_dn, "down")
            t_exit = math.inf
        else:
            # SLIP_BACKWARD: the part lags (carrier - part > 0), friction accelerates it forward
            direction = 1.0 if phase == SLIP_BACKWARD else -1.0
            acc = direction * slip
            seg = (direction, acc, part_x0, part_v0, t0)

            def relative(t: float, seg: tuple[float, ...] = seg) -> float:
                sgn, acc_, _, v0_, t0_ = seg
                return sgn * (carrier_at(t)[1] - (v0_ + acc_ * (t - t0_)))

            rel_grid = direction * (grid_v - (part_v0 + acc * (grid - t0)))
            found, _ = _first_root(relative, grid, rel_grid, index, t0)
            kind = "relvel"
            t_exit = math.inf
            if grid_x is not None:

                def room(t: float, seg: tuple[float, ...] = seg) -> float:
                    _, acc_, x0_, v0_, t0_ = seg
                    dt = t - t0_
                    return track - (x0_ + v0_ * dt + 0.5 * acc_ * dt * dt - carrier_at(t)[0])

                dtg = grid - t0
                room_grid = track - (part_x0 + part_v0 * dtg + 0.5 * acc * dtg * dtg - grid_x)
                limit_index = int(np.searchsorted(grid, min(found, end), side="right")) + 1
                t_exit, _ = _first_root(
                    room, grid[:limit_index], room_grid[:limit_index], index, t0
                )
        if min(found, t_exit) >= end:
            break
        if t_exit < found:
            dt = t_exit - t0
            cx = carrier_at(t_exit)[0]
            transitions.append((t_exit, phase, EXITED))
            starts.append(t_exit)
            phases.append(EXITED)
            x0s.append(part_x0 + part_v0 * dt + 0.5 * acc * dt * dt)
            v0s.append(part_v0 + acc * dt)
            offsets.append(x0s[-1] - cx)
            exit_t = t_exit
            break
        t_event = found
        cx, cv, ca = carrier_at(t_event)
        if phase == STICK:
            part_x0 = cx + offsets[-1]
            part_v0 = cv
            new_phase = SLIP_BACKWARD if kind == "up" else SLIP_FORWARD
        else:
            dt = t_event - t0
            part_x0 = part_x0 + part_v0 * dt + 0.5 * acc * dt * dt
            part_v0 = cv  # equal at the event
            if abs(ca) <= limit:
                new_phase = STICK
            else:
                new_phase = SLIP_BACKWARD if ca > 0.0 else SLIP_FORWARD
                if new_phase == phase:  # grazing: relative velocity touched zero and turned back
                    new_phase = SLIP_BACKWARD if phase == SLIP_FORWARD else SLIP_FORWARD
        transitions.append((t_event, phase, new_phase))
        starts.append(t_event)
        phases.append(new_phase)
        x0s.append(part_x0)
        v0s.append(part_v0)
        offsets.append(part_x0 - cx)
        t0, phase = t_event, new_phase
        index = max(1, int(np.searchsorted(grid, t_event, side="right")))

    track_result = PartTrack(
        start_t_s=np.array(starts),
        phase=np.array(phases, dtype=np.int8),
        x0_m=np.array(x0s),
        v0_mps=np.array(v0s),
        offset_m=np.array(offsets),
        slip_acceleration_mps2=slip,
        end_t_s=exit_t if math.isfinite(exit_t) else end,
        exit_t_s=exit_t,
    )
    return track_result, transitions


def _drive_forces(drive: DriveSchedule) -> tuple[ForceFunction, ScalarForce, list[float]]:
    segments = drive.segments()
    starts = [float(s) for s in segments.start_s]
    omega = [float(w) for w in segments.omega_rad_s]
    amp = [float(a) for a in segments.amplitude_n]
    phase = [float(p) for p in segments.phase_rad]

    def scalar(t: float) -> float:
        k = max(bisect.bisect_right(starts, t) - 1, 0)
        return amp[k] * math.sin(phase[k] + omega[k] * (t - starts[k]))

    if len(starts) == 1:  # constant drive: A*sin(phi0 + omega*t), the common case

        def scalar(t: float) -> float:
            return amp[0] * math.sin(phase[0] + omega[0] * t)

    def vector(t: FloatArray) -> FloatArray:
        return segments.force(t)

    return vector, scalar, starts[1:]


def _switch_events(carrier: LogisticCarrier, grid: _Grid) -> FloatArray:
    """Times where the switching variable (x or x') changes sign: the logistic 'branch switches'."""
    on_velocity = carrier.params.stiffness_switch == "velocity"
    values = grid.v if on_velocity else grid.x
    sign = np.sign(values)
    change = np.flatnonzero(sign[1:] * sign[:-1] < 0.0)
    column = 1 if on_velocity else 0

    def switch_value(t: float) -> float:
        return carrier.state_at(t)[column]

    times = [
        float(brentq(switch_value, float(grid.t[j]), float(grid.t[j + 1]), xtol=1e-15))
        for j in change
    ]
    return np.array(times, dtype=np.float64)


def simulate_smooth(
    params: FeederParameters,
    duration_s: float,
    output_rate_hz: float,
    parts: Sequence[PartSpec] = (),
    drive: DriveSchedule | None = None,
    options: SolverOptions | None = None,
) -> SimulationResult:
    """The logistic model (Eq. 6 + Eq. 9) with parts, in the same form as ``simulate``'s result.

    Samples at ``k/output_rate_hz``. The carrier branch code is the sign of the switching variable
    (+1 where ``K`` is nearer ``K_f``); ``BRANCH_SWITCH`` events are its sign changes. ``options``
    picks the ``solve_ivp`` method and tolerances (default :class:`SolverOptions`).
    """
    if not (output_rate_hz > 0.0 and math.isfinite(output_rate_hz)):
        raise ValueError(f"output_rate_hz={output_rate_hz!r} must be positive and finite")
    if not (duration_s > 0.0 and math.isfinite(duration_s)):
        raise ValueError(f"duration_s={duration_s!r} must be positive and finite")
    drive = drive or DriveSchedule(params.drive_frequency_hz, params.drive_amplitude_n)
    force, scalar_force, breakpoints = _drive_forces(drive)
    carrier = solve_logistic_carrier(
        params, duration_s, force, options, breakpoints, scalar_force=scalar_force
    )
    n = math.floor(duration_s * output_rate_hz * (1.0 + 1e-12))
    t = np.arange(n + 1, dtype=np.float64) / output_rate_hz
    cx, cv, ca = carrier.state(t)
    grid_t = carrier.scan_grid()
    gx, gv, ga = carrier.state(grid_t)
    grid = _Grid(grid_t, gx, gv, ga)

    events: list[tuple[float, int, int]] = [
        (float(ts), int(EventKind.BRANCH_SWITCH), -1) for ts in _switch_events(carrier, grid)
    ]
    seg = drive.segments()
    events += [
        (float(ts), int(EventKind.DRIVE_CHANGE), -1)
        for ts, logged in zip(seg.start_s[1:], seg.logged[1:], strict=True)
        if logged and ts <= duration_s
    ]
    kind_of = {
        (Phase.STICK, Phase.SLIP_FORWARD): EventKind.SLIP_START,
        (Phase.STICK, Phase.SLIP_BACKWARD): EventKind.SLIP_START,
        (Phase.SLIP_FORWARD, Phase.STICK): EventKind.STICK,
        (Phase.SLIP_BACKWARD, Phase.STICK): EventKind.STICK,
        (Phase.SLIP_FORWARD, Phase.SLIP_BACKWARD): EventKind.SLIP_REVERSAL,
        (Phase.SLIP_BACKWARD, Phase.SLIP_FORWARD): EventKind.SLIP_REVERSAL,
    }
    N = len(parts)
    part_x = np.empty((t.size, N))
    part_v = np.empty((t.size, N))
    part_phase = np.empty((t.size, N), dtype=np.int8)
    start_x, end_t, end_x = np.empty(N), np.empty(N), np.empty(N)
    slip_time, exit_t = np.empty(N), np.empty(N)
    for i, spec in enumerate(parts):
        _, mu_s, mu_d = spec.resolved(params)
        track, transitions = integrate_part(
            carrier, grid.t, grid.a, grid.v, spec.position_m, mu_s, mu_d, grid_x=grid.x
        )
        part_x[:, i], part_v[:, i], part_phase[:, i] = track.sample(t, cx, cv)
        for ts, before, after in transitions:
            kind = (
                EventKind.PART_EXIT if after == EXITED else kind_of[(Phase(before), Phase(after))]
            )
            events.append((ts, int(kind), i))
        start_x[i] = spec.position_m
        end_t[i] = track.end_t_s
        last_x, _, _ = track.sample(
            np.array([track.end_t_s if math.isfinite(track.exit_t_s) else duration_s]),
            *carrier.state(np.array([min(track.end_t_s, duration_s)]))[:2],
        )
        if math.isfinite(track.exit_t_s):
            end_x[i] = track.x0_m[-1]
        else:
            end_x[i] = float(last_x[0])
        slip_time[i] = track.slip_time_s
        exit_t[i] = track.exit_t_s
    events.sort(key=lambda event: event[0])
    return SimulationResult(
        t_s=t,
        carrier_x_m=cx,
        carrier_v_mps=cv,
        carrier_a_mps2=ca,
        branch=carrier.branch(cx, cv),
        part_x_m=part_x,
        part_v_mps=part_v,
        part_phase=part_phase,
        events=EventLog.of(
            np.array([e[0] for e in events], dtype=np.float64),
            np.array([e[1] for e in events], dtype=np.int8),
            np.array([e[2] for e in events], dtype=np.int64),
        ),
        part_start_t_s=np.zeros(N),
        part_start_x_m=start_x,
        part_end_t_s=end_t,
        part_end_x_m=end_x,
        part_slip_time_s=slip_time,
        part_exit_t_s=exit_t,
    )
