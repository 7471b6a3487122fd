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
    seg = drive.segments()
    n_out = math.floor(duration_s * output_rate_hz * (1.0 + 1e-12))
    samples = np.arange(n_out + 1, dtype=np.float64) / output_rate_hz
    cos_t = params.cos_theta
    kf = params.forward_stiffness_n_per_m * cos_t
    kb = params.backward_stiffness_n_per_m * cos_t
    c = params.damping_ns_per_m
    two_way = params.coupling == "two_way"
    velocity_switch = params.stiffness_switch == "velocity"
    kg = params.gravity_mps2 * params.friction_multiplier
    N = len(parts)
    res = [spec.resolved(params) for spec in parts]
    mass_p = np.array([r[0] for r in res])
    L = np.array([r[1] * kg for r in res])
    D = np.array([r[2] * kg for r in res])
    phase = np.zeros(N, dtype=np.int64)  # Phase codes; -1 exited
    track = params.track_length_m
    y = np.zeros(2 + 2 * N)
    for i, spec in enumerate(parts):
        y[2 + 2 * i] = spec.position_m
    mode = 1  # +1, -1, 0 held
    slip_time = np.zeros(N)
    exit_t = np.full(N, np.nan)
    end_x = np.full(N, np.nan)

    def carrier_mass_force() -> tuple[float, float]:
        if not two_way:
            return params.equivalent_mass_kg, 0.0
        m = params.carrier_mass_kg + params.mass_coefficient * params.plate_mass_kg
        r = 0.0
        for i in range(N):
            if phase[i] == Phase.STICK:
                m += mass_p[i]
            elif phase[i] == Phase.SLIP_BACKWARD:
                r -= mass_p[i] * D[i]
            elif phase[i] == Phase.SLIP_FORWARD:
                r += mass_p[i] * D[i]
        return m, r

    def force(t: float) -> float:
        return float(seg.force(t))

    def accel(t: float, x: float, v: float, m: float, r: float) -> float:
        if mode == 0:
            return 0.0
        k = kf if mode > 0 else kb
        return (force(t) + r - c * v - k * x) / m

    ev_t: list[float] = []
    ev_k: list[int] = []
    ev_p: list[int] = []
    out: dict[str, npt.NDArray[Any]] = {
        "cx": np.zeros(n_out + 1),
        "cv": np.zeros(n_out + 1),
        "ca": np.zeros(n_out + 1),
        "cb": np.zeros(n_out + 1, np.int8),
        "px": np.zeros((n_out + 1, N)),
        "pv": np.zeros((n_out + 1, N)),
        "pp": np.zeros((n_out + 1, N), np.int8),
    }

    def record(j: int, t: float) -> None:
        m, r = carrier_mass_force()
        out["cx"][j] = y[0]
        out["cv"][j] = y[1]
        out["ca"][j] = accel(t, y[0], y[1], m, r)
        out["cb"][j] = mode
        for i in range(N):
            if phase[i] < 0:
                out["px"][j, i] = np.nan
                out["pv"][j, i] = np.nan
                out["pp"][j, i] = Phase.EXITED
            else:
                out["px"][j, i] = y[2 + 2 * i]
                out["pv"][j, i] = y[3 + 2 * i]
                out["pp"][j, i] = phase[i]

    # stops: sample times, drive boundaries, end
    stops = np.union1d(samples, seg.start_s[(seg.start_s > 0) & (seg.start_s < duration_s)])
    t = 0.0
    j_out = 0
    if samples[0] == 0.0:
        record(0, 0.0)
        j_out = 1
    m0, r0 = carrier_mass_force()
    a0 = accel(0.0, y[0], y[1], m0, r0)
    for i in range(N):
        if abs(a0) > L[i]:
            phase[i] = Phase.SLIP_BACKWARD if a0 > 0 else Phase.SLIP_FORWARD
    stop_index = int(np.searchsorted(stops, 0.0, side="right"))
    guard = 0
    while stop_index < len(stops):
        t_stop = float(stops[stop_index])
        # a stick condition already violated at a restart (the acceleration jumped): slip now
        for _ in range(N):
            m, r = carrier_mass_force()
            a_now = accel(t, y[0], y[1], m, r)
            over = [i for i in range(N) if phase[i] == Phase.STICK and abs(a_now) > L[i]]
            if not over:
                break
            for i in over:
                phase[i] = Phase.SLIP_BACKWARD if a_now > 0 else Phase.SLIP_FORWARD
                ev_t.append(t)
                ev_k.append(EventKind.SLIP_START)
                ev_p.append(i)
        m, r = carrier_mass_force()
        mode_now = mode
        k = kf if mode_now >= 0 else kb
        kseg = seg.index_at(t)
        amp_k, om_k = float(seg.amplitude_n[kseg]), float(seg.omega_rad_s[kseg])
        ph_k, st_k = float(seg.phase_rad[kseg]), float(seg.start_s[kseg])

        def force_k(tt: float) -> float:
            return amp_k * math.sin(ph_k + om_k * (tt - st_k))  # noqa: B023

        def rhs(tt: float, yy: F64, m: float = m, r: float = r, k: float = k) -> F64:
            dy = np.empty_like(yy)
            if mode_now == 0:  # noqa: B023
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
            events.append(fn)  # noqa: B023
            tags.append(tag)  # noqa: B023

        if mode_now != 0:
            idx = 1 if velocity_switch else 0

            def branch(tt: float, yy: F64, idx: int = idx, s: float = mode_now) -> float:
                return float(s * yy[idx])

            add(branch, ("branch", -1))
        else:

            def slide_fwd(tt: float, yy: F64, r: float = r) -> float:
                return -(force_k(tt) + r - kf * float(yy[0]))

            def slide_bwd(tt: float, yy: F64, r: float = r) -> float:
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
        sol = solve_ivp(rhs, (t, t_stop), y, method="DOP853", rtol=rtol, atol=atol, events=events)
        if sol.status == -1:
            raise RuntimeError("solve_ivp failed: " + sol.message)
        for i in range(N):
            if phase[i] > 0:
                slip_time[i] += sol.t[-1] - t
        y = sol.y[:, -1].copy()
        t_new = float(sol.t[-1])
        if sol.status == 1:
            # which event fired
            assert sol.t_events is not None
            assert sol.y_events is not None
            which = next(n for n, te in enumerate(sol.t_events) if len(te))
            kind, i = tags[which]
            t_new = float(sol.t_events[which][0])
            y = sol.y_events[which][0].copy()
            m, r = carrier_mass_force()
            F = force_k(t_new)
            if kind == "branch":
                if velocity_switch:
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
                        new = mode
                else:
                    y[0] = 0.0
                    new = -mode
                ev_t.append(t_new)
                ev_k.append(EventKind.SLIDING_START if new == 0 else EventKind.BRANCH_SWITCH)
                ev_p.append(-1)
                mode = new
            elif kind in ("slide_fwd", "slide_bwd"):
                mode = 1 if kind == "slide_fwd" else -1
                ev_t.append(t_new)
                ev_k.append(EventKind.SLIDING_END)
                ev_p.append(-1)
            elif kind in ("up", "down"):
                phase[i] = Phase.SLIP_BACKWARD if kind == "up" else Phase.SLIP_FORWARD
                ev_t.append(t_new)
                ev_k.append(EventKind.SLIP_START)
                ev_p.append(i)
            elif kind == "relvel":
                y[3 + 2 * i] = y[1]
                k_now = kf if mode >= 0 else kb
                if two_way and mode != 0:
                    rs = r + (
                        mass_p[i] * D[i] if phase[i] == Phase.SLIP_BACKWARD else -mass_p[i] * D[i]
                    )
                    a_test = (F + rs - c * y[1] - k_now * y[0]) / (m + mass_p[i])
                else:
                    a_test = accel(t_new, y[0], y[1], m, r)
                if abs(a_test) <= L[i]:
                    phase[i] = Phase.STICK
                    ev_k.append(EventKind.STICK)
                else:
                    phase[i] = Phase.SLIP_BACKWARD if a_test > 0 else Phase.SLIP_FORWARD
                    ev_k.append(EventKind.SLIP_REVERSAL)
                ev_t.append(t_new)
                ev_p.append(i)
            elif kind == "exit":
                phase[i] = -1
                exit_t[i] = t_new
                end_x[i] = y[2 + 2 * i]
                ev_t.append(t_new)
                ev_k.append(EventKind.PART_EXIT)
                ev_p.append(i)
            guard = guard + 1 if t_new == t else 0
            if guard > 100:
                raise RuntimeError(f"reference stuck at t={t_new}")
        else:
            if t_stop in seg.start_s:
                kseg = int(np.searchsorted(seg.start_s, t_stop))
                if seg.logged[kseg]:
                    ev_t.append(t_stop)
                    ev_k.append(EventKind.DRIVE_CHANGE)
                    ev_p.append(-1)
            stop_index += 1
        t = t_new
        if t == t_stop or sol.status == 0:
            t = t_stop
            while j_out <= n_out and samples[j_out] <= t:
                if samples[j_out] == t:
                    record(j_out, t)
                j_out += 1
    for i in range(N):
        if phase[i] >= 0:
            end_x[i] = y[2 + 2 * i]
    start_x = np.array([spec.position_m for spec in parts])
    return SimulationResult(
        t_s=samples,
        carrier_x_m=out["cx"],
        carrier_v_mps=out["cv"],
        carrier_a_mps2=out["ca"],
        branch=out["cb"],
        part_x_m=out["px"],
        part_v_mps=out["pv"],
        part_phase=out["pp"],
        events=EventLog.of(np.array(ev_t), np.array(ev_k, np.int8), np.array(ev_p, np.int64)),
        part_start_t_s=np.zeros(N),
        part_start_x_m=start_x,
        part_end_t_s=np.where(np.isfinite(exit_t), exit_t, duration_s),
        part_end_x_m=end_x,
        part_slip_time_s=slip_time,
        part_exit_t_s=exit_t,
    )
