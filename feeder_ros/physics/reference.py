"""Reference solution of the sharp model with ``solve_ivp`` (DOP853), for tests and benchmarks.

The same hybrid model as :mod:`feeder_ros.physics.simulation`, written independently and naively:
one ODE state ``[x, v, p_1, u_1, ..., p_N, u_N]`` (lab positions/velocities, no grouping), the
integrator restarted at every event (branch switch, sliding start/end, slip onset, relative velocity
zero, track exit), at every drive segment boundary and at every output time (so that samples are
integrator steps, not dense-output interpolations). Event roots are located by ``solve_ivp``'s
terminal events (Brent, ``xtol = 4*eps``). It is slow (a Python callback per right-hand-side
evaluation) and meant for short horizons only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.integrate import solve_ivp

from feeder_ros.physics.drive import DriveSchedule
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import EventKind, EventLog, PartSpec, Phase, SimulationResult

__all__ = ["reference_simulate"]

F64 = npt.NDArray[np.float64]
EventFn = Callable[[float, F64], float]


def reference_simulate(
    params: FeederParameters,
    duration_s: float,
    output_rate_hz: float,
    parts: Sequence[PartSpec] = (PartSpec(),),
    drive: DriveSchedule | None = None,
    rtol: float = 1e-12,
    atol: float = 1e-22,
) -> SimulationResult:
    """Simulate like :func:`~feeder_ros.physics.simulation.simulate` (sharp model) with DOP853."""
    drive = drive or DriveSchedule(params.drive_frequency_hz, params.drive_amplitude_n)
    run = _ReferenceRun(params, drive, duration_s, output_rate_hz, parts)
    run.integrate(duration_s, rtol, atol)
    return run.result(duration_s, parts)


class _ReferenceRun:
    """The state of one reference run: carrier and parts in one ODE state ``y``, the carrier's
    stiffness mode, the parts' phases, the event log and the output arrays."""

    def __init__(
        self,
        params: FeederParameters,
        drive: DriveSchedule,
        duration_s: float,
        output_rate_hz: float,
        parts: Sequence[PartSpec],
    ) -> None:
        self.params = params
        self.seg = drive.segments()
        self.n_out = math.floor(duration_s * output_rate_hz * (1.0 + 1e-12))
        self.samples = np.arange(self.n_out + 1, dtype=np.float64) / output_rate_hz
        cos_t = params.cos_theta
        self.kf = params.forward_stiffness_n_per_m * cos_t
        self.kb = params.backward_stiffness_n_per_m * cos_t
        self.c = params.damping_ns_per_m
        self.two_way = params.coupling == "two_way"
        self.velocity_switch = params.stiffness_switch == "velocity"
        kg = params.gravity_mps2 * params.friction_multiplier
        self.N = N = len(parts)
        res = [spec.resolved(params) for spec in parts]
        self.mass_p = np.array([r[0] for r in res])
        self.L = np.array([r[1] * kg for r in res])
        self.D = np.array([r[2] * kg for r in res])
        self.phase = np.zeros(N, dtype=np.int64)  # Phase codes; -1 exited
        self.track = params.track_length_m
        self.y = np.zeros(2 + 2 * N)
        for i, spec in enumerate(parts):
            self.y[2 + 2 * i] = spec.position_m
        self.mode = 1  # +1, -1, 0 held
        self.slip_time = np.zeros(N)
        self.exit_t = np.full(N, np.nan)
        self.end_x = np.full(N, np.nan)
        self.ev_t: list[float] = []
        self.ev_k: list[int] = []
        self.ev_p: list[int] = []
        n = self.n_out + 1
        self.out: dict[str, npt.NDArray[Any]] = {
            "cx": np.zeros(n),
            "cv": np.zeros(n),
            "ca": np.zeros(n),
            "cb": np.zeros(n, np.int8),
            "px": np.zeros((n, N)),
            "pv": np.zeros((n, N)),
            "pp": np.zeros((n, N), np.int8),
        }

    def carrier_mass_force(self) -> tuple[float, float]:
        params, phase = self.params, self.phase
        if not self.two_way:
            return params.equivalent_mass_kg, 0.0
        m = params.carrier_mass_kg + params.mass_coefficient * params.plate_mass_kg
        r = 0.0
        for i in range(self.N):
            if phase[i] == Phase.STICK:
                m += self.mass_p[i]
            elif phase[i] == Phase.SLIP_BACKWARD:
                r -= self.mass_p[i] * self.D[i]
            elif phase[i] == Phase.SLIP_FORWARD:
                r += self.mass_p[i] * self.D[i]
        return m, r

    def accel(self, t: float, x: float, v: float, m: float, r: float) -> float:
        if self.mode == 0:
            return 0.0
        k = self.kf if self.mode > 0 else self.kb
        return (float(self.seg.force(t)) + r - self.c * v - k * x) / m

    def log(self, t: float, kind: int, part: int) -> None:
        self.ev_t.append(t)
        self.ev_k.append(kind)
        self.ev_p.append(part)

    def record(self, j: int, t: float) -> None:
        out, y, phase = self.out, self.y, self.phase
        m, r = self.carrier_mass_force()
        out["cx"][j] = y[0]
        out["cv"][j] = y[1]
        out["ca"][j] = self.accel(t, y[0], y[1], m, r)
        out["cb"][j] = self.mode
        for i in range(self.N):
            if phase[i] < 0:
                out["px"][j, i] = np.nan
                out["pv"][j, i] = np.nan
                out["pp"][j, i] = Phase.EXITED
            else:
                out["px"][j, i] = y[2 + 2 * i]
                out["pv"][j, i] = y[3 + 2 * i]
                out["pp"][j, i] = phase[i]

    def slip_where_violated(self, t: float) -> None:
        """A stick condition already violated at a restart (the acceleration jumped): slip now."""
        for _ in range(self.N):
            m, r = self.carrier_mass_force()
            a_now = self.accel(t, self.y[0], self.y[1], m, r)
            over = [
                i for i in range(self.N) if self.phase[i] == Phase.STICK and abs(a_now) > self.L[i]
            ]
            if not over:
                break
            for i in over:
                self.phase[i] = Phase.SLIP_BACKWARD if a_now > 0 else Phase.SLIP_FORWARD
                self.log(t, EventKind.SLIP_START, i)

    def integrate(self, duration_s: float, rtol: float, atol: float) -> None:
        """From 0 to ``duration_s``: pieces between stops (samples, drive changes), each cut at
        its first event, the integrator restarted after each."""
        seg, samples, n_out = self.seg, self.samples, self.n_out
        stops = np.union1d(samples, seg.start_s[(seg.start_s > 0) & (seg.start_s < duration_s)])
        t = 0.0
        j_out = 0
        if samples[0] == 0.0:
            self.record(0, 0.0)
            j_out = 1
        m0, r0 = self.carrier_mass_force()
        a0 = self.accel(0.0, self.y[0], self.y[1], m0, r0)
        for i in range(self.N):
            if abs(a0) > self.L[i]:
                self.phase[i] = Phase.SLIP_BACKWARD if a0 > 0 else Phase.SLIP_FORWARD
        stop_index = int(np.searchsorted(stops, 0.0, side="right"))
        guard = 0
        while stop_index < len(stops):
            t_stop = float(stops[stop_index])
            self.slip_where_violated(t)
            rhs, events, tags, force_k = _piece(self, t)
            sol = solve_ivp(
                rhs, (t, t_stop), self.y, method="DOP853", rtol=rtol, atol=atol, events=events
            )
            if sol.status == -1:
                raise RuntimeError("solve_ivp failed: " + sol.message)
            for i in range(self.N):
                if self.phase[i] > 0:
                    self.slip_time[i] += sol.t[-1] - t
            self.y = sol.y[:, -1].copy()
            t_new = float(sol.t[-1])
            if sol.status == 1:
                # which event fired
                assert sol.t_events is not None
                assert sol.y_events is not None
                which = next(n for n, te in enumerate(sol.t_events) if len(te))
                kind, i = tags[which]
                t_new = float(sol.t_events[which][0])
                self.y = sol.y_events[which][0].copy()
                self.event(kind, i, t_new, force_k(t_new))
                guard = guard + 1 if t_new == t else 0
                if guard > 100:
                    raise RuntimeError(f"reference stuck at t={t_new}")
            else:
                if t_stop in seg.start_s:
                    kseg = int(np.searchsorted(seg.start_s, t_stop))
                    if seg.logged[kseg]:
                        self.log(t_stop, EventKind.DRIVE_CHANGE, -1)
                stop_index += 1
            t = t_new
            if t == t_stop or sol.status == 0:
                t = t_stop
                while j_out <= n_out and samples[j_out] <= t:
                    if samples[j_out] == t:
                        self.record(j_out, t)
                    j_out += 1

    def event(self, kind: str, i: int, t_new: float, F: float) -> None:
        """The event ``kind`` (part ``i``'s, if a part's) at ``t_new``, the drive force ``F``
        there: the carrier's mode, a part's phase, the state ``y`` changed and the event logged."""
        y, phase, mass_p, D, L = self.y, self.phase, self.mass_p, self.D, self.L
        kf, kb = self.kf, self.kb
        m, r = self.carrier_mass_force()
        if kind == "branch":
            if self.velocity_switch:
                y[1] = 0.0
                af = (F + r - kf * y[0]) / m
                ab = (F + r - kb * y[0]) / m
                if af > 0 and ab > 0:
                    new = 1
                elif af < 0 and ab < 0:
                    new = -1
                elif af <= 0 <= ab:
                    new = 0
                else:
                    new = self.mode
            else:
                y[0] = 0.0
                new = -self.mode
            self.log(t_new, EventKind.SLIDING_START if new == 0 else EventKind.BRANCH_SWITCH, -1)
            self.mode = new
        elif kind in ("slide_fwd", "slide_bwd"):
            self.mode = 1 if kind == "slide_fwd" else -1
            self.log(t_new, EventKind.SLIDING_END, -1)
        elif kind in ("up", "down"):
            phase[i] = Phase.SLIP_BACKWARD if kind == "up" else Phase.SLIP_FORWARD
            self.log(t_new, EventKind.SLIP_START, i)
        elif kind == "relvel":
            y[3 + 2 * i] = y[1]
            k_now = kf if self.mode >= 0 else kb
            if self.two_way and self.mode != 0:
                rs = r + (
                    mass_p[i] * D[i] if phase[i] == Phase.SLIP_BACKWARD else -mass_p[i] * D[i]
                )
                a_test = (F + rs - self.c * y[1] - k_now * y[0]) / (m + mass_p[i])
            else:
                a_test = self.accel(t_new, y[0], y[1], m, r)
            if abs(a_test) <= L[i]:
                phase[i] = Phase.STICK
                self.log(t_new, EventKind.STICK, i)
            else:
                phase[i] = Phase.SLIP_BACKWARD if a_test > 0 else Phase.SLIP_FORWARD
                self.log(t_new, EventKind.SLIP_REVERSAL, i)
        elif kind == "exit":
            phase[i] = -1
            self.exit_t[i] = t_new
            self.end_x[i] = y[2 + 2 * i]
            self.log(t_new, EventKind.PART_EXIT, i)

    def result(self, duration_s: float, parts: Sequence[PartSpec]) -> SimulationResult:
        N, y, out = self.N, self.y, self.out
        for i in range(N):
            if self.phase[i] >= 0:
                self.end_x[i] = y[2 + 2 * i]
        start_x = np.array([spec.position_m for spec in parts])
        return SimulationResult(
            t_s=self.samples,
            carrier_x_m=out["cx"],
            carrier_v_mps=out["cv"],
            carrier_a_mps2=out["ca"],
            branch=out["cb"],
            part_x_m=out["px"],
            part_v_mps=out["pv"],
            part_phase=out["pp"],
            events=EventLog.of(
                np.array(self.ev_t), np.array(self.ev_k, np.int8), np.array(self.ev_p, np.int64)
            ),
            part_start_t_s=np.zeros(N),
            part_start_x_m=start_x,
            part_end_t_s=np.where(np.isfinite(self.exit_t), self.exit_t, duration_s),
            part_end_x_m=self.end_x,
            part_slip_time_s=self.slip_time,
            part_exit_t_s=self.exit_t,
        )


def _piece(
    run: _ReferenceRun, t: float
) -> tuple[
    Callable[[float, F64], F64], list[EventFn], list[tuple[str, int]], Callable[[float], float]
]:
    """The ODE of the piece starting at ``t`` (the mode, phases and carrier load as they are
    now), its terminal event functions with their tags, and the drive force in it."""
    seg, phase, L, D, N = run.seg, run.phase, run.L, run.D, run.N
    c, kf, kb, track = run.c, run.kf, run.kb, run.track
    m, r = run.carrier_mass_force()
    mode_now = run.mode
    k = kf if mode_now >= 0 else kb
    kseg = seg.index_at(t)
    amp_k, om_k = float(seg.amplitude_n[kseg]), float(seg.omega_rad_s[kseg])
    ph_k, st_k = float(seg.phase_rad[kseg]), float(seg.start_s[kseg])

    def force_k(tt: float) -> float:
        return amp_k * math.sin(ph_k + om_k * (tt - st_k))

    def rhs(tt: float, yy: F64) -> F64:
        dy = np.empty_like(yy)
        if mode_now == 0:
            a = 0.0
            dy[0] = 0.0
        else:
            a = (force_k(tt) + r - c * yy[1] - k * yy[0]) / m
            dy[0] = yy[1]
        dy[1] = a
        for i in range(N):
            dy[2 + 2 * i] = yy[3 + 2 * i]
            if phase[i] == Phase.STICK:
                dy[3 + 2 * i] = a
            elif phase[i] == Phase.SLIP_BACKWARD:
                dy[3 + 2 * i] = D[i]
            elif phase[i] == Phase.SLIP_FORWARD:
                dy[3 + 2 * i] = -D[i]
            else:
                dy[3 + 2 * i] = 0.0
        return dy

    events: list[EventFn] = []
    tags: list[tuple[str, int]] = []

    def add(fn: EventFn, tag: tuple[str, int]) -> None:
        fn.terminal = True  # type: ignore[attr-defined]
        fn.direction = -1  # type: ignore[attr-defined]
        events.append(fn)
        tags.append(tag)

    if mode_now != 0:
        idx = 1 if run.velocity_switch else 0

        def branch(tt: float, yy: F64, idx: int = idx, s: float = mode_now) -> float:
            return float(s * yy[idx])

        add(branch, ("branch", -1))
    else:

        def slide_fwd(tt: float, yy: F64) -> float:
            return -(force_k(tt) + r - kf * float(yy[0]))

        def slide_bwd(tt: float, yy: F64) -> float:
            return force_k(tt) + r - kb * float(yy[0])

        add(slide_fwd, ("slide_fwd", -1))
        add(slide_bwd, ("slide_bwd", -1))
    for i in range(N):
        if phase[i] == Phase.STICK:

            def up(tt: float, yy: F64, i: int = i) -> float:
                return float(L[i] - rhs(tt, yy)[1])

            def down(tt: float, yy: F64, i: int = i) -> float:
                return float(L[i] + rhs(tt, yy)[1])

            add(up, ("up", i))
            add(down, ("down", i))
        elif phase[i] > 0:
            s = 1.0 if phase[i] == Phase.SLIP_BACKWARD else -1.0

            def relvel(tt: float, yy: F64, i: int = i, s: float = s) -> float:
                return float(s * (yy[1] - yy[3 + 2 * i]))

            def leave(tt: float, yy: F64, i: int = i) -> float:
                return float(track - (yy[2 + 2 * i] - yy[0]))

            add(relvel, ("relvel", i))
            add(leave, ("exit", i))
    return rhs, events, tags, force_k
