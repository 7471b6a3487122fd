"""The live, stateful exact simulator (:class:`FeederSimulator`): advance in chunks, change the
drive, the parameters and the parts while it runs; the group and member tables it hands to the
exact engine's kernels, and the numba thread limit for parallel group passes.

The model and the engine: :mod:`feeder_ros.physics.simulation` and
:mod:`feeder_ros.physics.exact`.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from typing import Any

import numba
import numpy as np
import numpy.typing as npt

from feeder_ros.physics.drive import DriveChange, DriveSchedule
from feeder_ros.physics.errors import SimulationError
from feeder_ros.physics.exact import (
    event_steps,
    global_loop,
    group_march,
    layout,
    ordering,
    recorded_pieces,
    sampling,
)
from feeder_ros.physics.group_tables import _Groups, _Members, _output_arrays
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.parameters import finite_number as _finite
from feeder_ros.physics.results import (
    F64,
    I8,
    I64,
    EventArrays,
    EventKind,
    EventLog,
    PartSpec,
    SimulationResult,
)

__all__ = ["FORGET_DRIVE_CHANGES_AFTER", "FeederSimulator", "limited_threads"]

#: group-pieces below which a parallel group pass runs on one thread
SMALL_PARALLEL_WORK = 4096
#: drive changes a live simulator keeps before it forgets those already in the past
#: (:meth:`DriveSchedule.forget_before`; the drive from the present on is unchanged)
FORGET_DRIVE_CHANGES_AFTER = 8


def _model_vector(params: FeederParameters, log_events: bool = True) -> F64:
    model = np.zeros(layout.MODEL_SIZE)
    cos_t = params.cos_theta
    model[layout.M_ONEWAY] = params.equivalent_mass_kg
    model[layout.M_BASE] = params.carrier_mass_kg + params.mass_coefficient * params.plate_mass_kg
    model[layout.DAMPING] = params.damping_ns_per_m
    model[layout.K_FWD] = params.forward_stiffness_n_per_m * cos_t
    model[layout.K_BWD] = params.backward_stiffness_n_per_m * cos_t
    model[layout.TRACK] = params.track_length_m
    model[layout.SWITCH] = 0.0 if params.stiffness_switch == "displacement" else 1.0
    model[layout.COUPLING] = 0.0 if params.coupling == "one_way" else 1.0
    model[layout.LOG_EVENTS] = 1.0 if log_events else 0.0
    return model


def _default_drive(params: FeederParameters) -> DriveSchedule:
    return _constant_drive(params.drive_frequency_hz, params.drive_amplitude_n)


@functools.lru_cache(maxsize=256)
def _constant_drive(frequency_hz: float, amplitude_n: float) -> DriveSchedule:
    # a schedule is immutable and caches its segments: simulators of one operating point share it
    return DriveSchedule(frequency_hz, amplitude_n)


class FeederSimulator:
    """Stateful exact simulator (sharp model) for the live node: advance in chunks, change live.

    ``FeederSimulator(params, parts, drive=None, initial_x_m=0.0, initial_v_mps=0.0)``; ``drive``
    defaults to a constant drive at ``params.drive_frequency_hz``/``drive_amplitude_n``. Advancing
    in chunks gives the same trajectory as one long run to round-off (the state is kept exactly,
    nothing is re-integrated; each chunk restarts the closed form from the exact state).
    """

    def __init__(
        self,
        params: FeederParameters,
        parts: Sequence[PartSpec] = (PartSpec(),),
        drive: DriveSchedule | None = None,
        initial_x_m: float = 0.0,
        initial_v_mps: float = 0.0,
    ) -> None:
        if params.stiffness_model != "sharp":
            raise ParameterError(
                f"stiffness_model={params.stiffness_model!r}: "
                "FeederSimulator solves the sharp model"
            )
        self._initial_params = params
        self._initial_parts = tuple(parts)
        self._initial_drive = drive if drive is not None else _default_drive(params)
        self._initial_xv = (
            _finite("initial_x_m", initial_x_m),
            _finite("initial_v_mps", initial_v_mps),
        )
        self.reset()

    # -- state ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to t = 0 with the constructor's parameters, parts, drive and initial state."""
        self._params = self._initial_params
        self._drive = self._initial_drive
        self._model = _model_vector(self._params)
        self._state = np.zeros(layout.STATE_SIZE)
        self._state[layout.S_X], self._state[layout.S_V] = self._initial_xv
        self._pending_events: list[tuple[float, int, int]] = []
        self._specs: list[PartSpec] = []
        self._g = _Groups.empty()
        self._m = _Members.empty()
        self._state[layout.S_MODE] = self._classify()
        self._spawn_initial(self._initial_parts)

    @property
    def time_s(self) -> float:
        return float(self._state[layout.S_T])

    @property
    def params(self) -> FeederParameters:
        return self._params

    @property
    def drive(self) -> DriveSchedule:
        return self._drive

    @property
    def part_count(self) -> int:
        """Parts ever put on the track (exited ones included; indices are stable)."""
        return len(self._specs)

    @property
    def carrier_state(self) -> tuple[float, float, int]:
        """(x_m, v_mps, branch) now."""
        return (
            float(self._state[layout.S_X]),
            float(self._state[layout.S_V]),
            int(self._state[layout.S_MODE]),
        )

    def _drive_now(self) -> tuple[float, float]:
        seg = self._drive.segments()
        k = seg.index_at(self.time_s)
        t = self.time_s
        phase = seg.phase_rad[k] + seg.omega_rad_s[k] * (t - seg.start_s[k])
        return (
            float(seg.amplitude_n[k] * math.sin(phase)),
            float(seg.amplitude_n[k] * seg.omega_rad_s[k] * math.cos(phase)),
        )

    def _carrier_mass_and_reaction(self) -> tuple[float, float]:
        if self._params.coupling == "one_way":
            return float(self._model[layout.M_ONEWAY]), 0.0
        mass = float(self._model[layout.M_BASE])
        reaction = 0.0
        g = self._g
        for i in range(g.size):
            if g.head[i] < 0:
                continue
            if g.phase[i] == layout.STICK:
                mass += g.mass[i]
            elif g.phase[i] == layout.SLIP_BACKWARD:
                reaction -= g.mass[i] * g.D[i]
            else:
                reaction += g.mass[i] * g.D[i]
        return mass, reaction

    def _classify(self) -> float:
        x, v = float(self._state[layout.S_X]), float(self._state[layout.S_V])
        force, dforce = self._drive_now()
        mass, reaction = self._carrier_mass_and_reaction()
        mode = float(self._state[layout.S_MODE]) if self._state[layout.S_MODE] != 0.0 else 1.0
        return float(
            event_steps._classify(
                int(self._model[layout.SWITCH]),
                mode,
                x,
                v,
                force,
                dforce,
                reaction,
                mass,
                float(self._model[layout.K_FWD]),
                float(self._model[layout.K_BWD]),
            )
        )

    # -- parts ---------------------------------------------------------------------------
    def spawn_part(self, spec: PartSpec, at_rest: bool = False) -> int:
        """Put a part on the track now at ``spec.position_m``; returns its index.

        By default it moves with the carrier (sticking). ``at_rest``: it is let go at rest in
        the lab, as a bowl's exit or a hand puts a part down, and slips until friction takes it
        along. The difference matters on a vibrating track: a part given the carrier's velocity
        at its backward peak (about 0.09 m/s at 30 Hz) slides back some 5 mm before friction
        stops it; one let go at rest stays within the carrier's stroke."""
        mass, mu_s, mu_d = spec.resolved(self._params)
        kappa_g = self._params.gravity_mps2 * self._params.friction_multiplier
        L, D = mu_s * kappa_g, mu_d * kappa_g
        index = len(self._specs)
        self._specs.append(spec)
        carrier_v = float(self._state[layout.S_V])
        if at_rest and carrier_v != 0.0:
            phase = layout.SLIP_FORWARD if carrier_v < 0.0 else layout.SLIP_BACKWARD
            g = self._g.slipping_group(L, D, phase, 0.0)
            if g < 0:
                g = self._g.add(L, D, 0.0)
                self._g.phase[g] = phase
        else:
            g = self._g.sticking_group(L, D)
            if g < 0:
                g = self._g.add(L, D, carrier_v)
        self._m.add(
            group=g,
            offset=spec.position_m - self._g.y[g],
            mass=mass,
            slip0=self._g.slip[g],
            start_t=self.time_s,
            start_x=spec.position_m + float(self._state[layout.S_X]),
        )
        self._g.join(g, index, self._m, mass)
        return index

    def _spawn_initial(self, specs: Sequence[PartSpec]) -> None:
        """Put the constructor's parts on the track at t = 0, grouped by friction (vectorised)."""
        self._specs = list(specs)
        N = len(specs)
        if N == 0:
            return
        kappa_g = self._params.gravity_mps2 * self._params.friction_multiplier
        if N <= 64:
            self._spawn_few(specs, kappa_g)
            return
        resolved = np.array([spec.resolved(self._params) for spec in specs], dtype=np.float64)
        mass = resolved[:, 0]
        friction = resolved[:, 1:] * kappa_g
        keys, group = np.unique(friction, axis=0, return_inverse=True)
        group = group.ravel().astype(np.int64)
        G = keys.shape[0]
        g = _Groups(G)
        g.L[:], g.D[:] = keys[:, 0], keys[:, 1]
        g.u[:] = self._state[layout.S_V]
        g.mass[:] = np.bincount(group, weights=mass, minlength=G)
        offset = np.array([spec.position_m for spec in specs], dtype=np.float64)
        g.lead[:] = -np.inf
        np.maximum.at(g.lead, group, offset)
        # linked lists: each member points to the next member of its group
        nxt = np.full(N, -1, np.int64)
        order = np.argsort(group, kind="stable")
        same = group[order][1:] == group[order][:-1]
        nxt[order[:-1][same]] = order[1:][same]
        g.head[:] = -1
        first = np.ones(N, bool)
        first[1:] = ~same
        g.head[group[order][first]] = order[first]
        m = _Members()
        m.size = N
        m.group = group
        m.next = nxt
        m.offset = offset
        m.mass = mass.copy()
        m.slip0 = np.zeros(N)
        m.exit_t = np.full(N, np.nan)
        m.start_t = np.zeros(N)
        m.start_x = offset + self._state[layout.S_X]
        self._g, self._m = g, m

    def _spawn_few(self, specs: Sequence[PartSpec], kappa_g: float) -> None:
        """:meth:`_spawn_initial` for a few parts: the same arrays, built from plain Python lists
        (the vectorised form, or numpy element by element, costs more than the simulation of a
        short run)."""
        N = len(specs)
        resolved = [spec.resolved(self._params) for spec in specs]
        friction = [(mu_s * kappa_g, mu_d * kappa_g) for _, mu_s, mu_d in resolved]
        keys = sorted(set(friction))  # the order of np.unique(axis=0)
        index = {key: i for i, key in enumerate(keys)}
        G = len(keys)
        group = [index[f] for f in friction]
        offset = [spec.position_m for spec in specs]
        mass = [r[0] for r in resolved]
        g_mass = [0.0] * G
        g_lead = [-math.inf] * G
        g_head = [-1] * G
        nxt = [-1] * N
        last = [-1] * G
        for i in range(N):
            gi = group[i]
            g_mass[gi] += mass[i]
            if offset[i] > g_lead[gi]:
                g_lead[gi] = offset[i]
            if last[gi] < 0:
                g_head[gi] = i
            else:
                nxt[last[gi]] = i
            last[gi] = i
        v0 = float(self._state[layout.S_V])
        x0 = float(self._state[layout.S_X])
        # the fields of one kind come from one array, each field a contiguous row of it (the
        # tables replace, never resize, their arrays)
        g = _Groups.__new__(_Groups)  # every field set below
        g.size = G
        g.L, g.D, g.mass, g.u, g.y, g.slip, g.lead = np.array(
            [[key[0] for key in keys], [key[1] for key in keys], g_mass, [v0] * G, [0.0] * G,
             [0.0] * G, g_lead],
            np.float64,
        )  # fmt: skip
        g.phase = np.zeros(G, np.int8)
        g.head = np.array(g_head, np.int64)
        m = _Members.__new__(_Members)  # every field set below
        m.size = N
        m.group, m.next = np.array([group, nxt], np.int64)
        m.offset, m.mass, m.slip0, m.exit_t, m.start_t, m.start_x = np.array(
            [offset, mass, [0.0] * N, [math.nan] * N, [0.0] * N, [o + x0 for o in offset]],
            np.float64,
        )
        self._g, self._m = g, m

    def _regroup(self) -> None:
        """Rebuild groups after friction/mass changes: split mixed groups, merge equal sticking
        ones."""
        kappa_g = self._params.gravity_mps2 * self._params.friction_multiplier
        old, members = self._g, self._m
        new = _Groups.empty()
        key_to_group: dict[tuple[int, float, float], int] = {}
        order = [i for i in range(members.size) if members.group[i] >= 0]
        for i in order:
            _, mu_s, mu_d = self._specs[i].resolved(self._params)
            mass = members.mass[i]
            L, D = mu_s * kappa_g, mu_d * kappa_g
            og = int(members.group[i])
            ph = int(old.phase[og])
            key = (og, L, D) if ph != layout.STICK else (-1, L, D)
            ng = key_to_group.get(key, -1)
            if ng < 0:
                ng = new.add(L, D, float(old.u[og]))
                new.phase[ng] = old.phase[og]
                new.y[ng] = old.y[og]
                new.slip[ng] = old.slip[og]
                key_to_group[key] = ng
            members.offset[i] += old.y[og] - new.y[ng]
            members.slip0[i] += new.slip[ng] - old.slip[og]
            members.group[i] = ng
            new.join(ng, i, members, mass)
        self._g = new

    def set_part_friction(
        self, static_friction: float, kinetic_friction: float, part: int | None = None
    ) -> None:
        """Change the friction of one part (``part`` index) or of all parts from now on."""
        mu_s = _finite("static_friction", static_friction, positive=True)
        mu_d = _finite("kinetic_friction", kinetic_friction, positive=True)
        if mu_d > mu_s:
            raise ParameterError(
                f"kinetic_friction={mu_d!r} must not exceed static_friction={mu_s!r}"
            )
        if part is not None and (
            isinstance(part, bool)
            or not isinstance(part, int | np.integer)
            or not 0 <= part < len(self._specs)
        ):
            raise ParameterError(f"part={part!r} is not a part index (0..{len(self._specs) - 1})")
        targets = range(len(self._specs)) if part is None else [int(part)]
        for i in targets:
            self._specs[i] = replace(self._specs[i], static_friction=mu_s, kinetic_friction=mu_d)
        self._regroup()

    def set_parameters(self, params: FeederParameters) -> None:
        """Use new parameters from now on (damping, friction, track length, stiffness, masses, ...).

        The state is kept: the carrier's displacement and velocity and every part's state carry
        over unchanged (a drifting stiffness or load changes the carrier's acceleration, not its
        motion), and the drive schedule continues phase-continuously. A new Young's modulus or
        plate geometry changes both spring branches; new masses change ``M_eq`` (and, with
        two-way coupling, the parts' masses). The stiffness branch is re-classified at once.
        """
        if params.stiffness_model != "sharp":
            raise ParameterError(
                f"stiffness_model={params.stiffness_model!r}: "
                "FeederSimulator solves the sharp model"
            )
        # every part resolved first: a refused change (a part's own friction against the new
        # defaults) raises before anything is changed
        masses = [spec.resolved(params)[0] for spec in self._specs]
        self._params = params
        self._model = _model_vector(params)
        for i, mass in enumerate(masses):
            self._m.mass[i] = mass
        self._regroup()
        self._state[layout.S_MODE] = self._classify()  # the switching variable may have changed

    # -- drive ---------------------------------------------------------------------------
    def set_drive(
        self,
        frequency_hz: float,
        amplitude_n: float,
        at_time_s: float | None = None,
        ramp_s: float = 0.0,
    ) -> None:
        """Drive at ``frequency_hz``/``amplitude_n`` from ``at_time_s`` (default: now), ramped over
        ``ramp_s``; replaces whatever was scheduled from that time on."""
        at = self.time_s if at_time_s is None else _finite("at_time_s", at_time_s)
        if at < self.time_s:
            raise ParameterError(f"at_time_s={at!r} is before the simulator time {self.time_s!r}")
        if len(self._drive.changes) > FORGET_DRIVE_CHANGES_AFTER:
            # a live run gets a command per tick while ramping: without this the schedule (and
            # the cost of rebuilding it on every command) would grow with the run's length
            self._drive = self._drive.forget_before(self.time_s)
        self._drive = self._drive.with_change(DriveChange(at, frequency_hz, amplitude_n, ramp_s))
        if at == self.time_s:
            self._pending_events.append((at, int(EventKind.DRIVE_CHANGE), -1))

    # -- running -------------------------------------------------------------------------
    def advance(
        self, t_end_s: float, sample_times_s: npt.ArrayLike | None = None
    ) -> SimulationResult:
        """Advance to ``t_end_s``; samples at ``sample_times_s`` (sorted, in ``[time_s, t_end_s]``).

        Returns the chunk's samples and events; the per-part totals (``part_*_s``/``part_*_m``)
        cover the simulator's whole life.
        """
        t_end = _finite("t_end_s", t_end_s)
        if t_end < self.time_s:
            raise ParameterError(
                f"t_end_s={t_end_s!r} is before the simulator time {self.time_s!r}"
            )
        samples = (
            np.zeros(0)
            if sample_times_s is None
            else np.ascontiguousarray(sample_times_s, dtype=np.float64).ravel()
        )
        if samples.size:
            if t_end == self.time_s:
                raise ParameterError(
                    f"t_end_s={t_end_s!r} equals the simulator time: nothing to sample"
                )
            problem = sampling.check_samples(samples)  # one pass, no temporaries
            if problem == 1:
                raise ParameterError("sample_times_s contains non-finite values")
            if problem == 2:
                raise ParameterError("sample_times_s must be sorted")
            if samples[0] < self.time_s or samples[-1] > t_end:
                raise ParameterError(
                    f"sample_times_s [{samples[0]!r}, {samples[-1]!r}] outside "
                    f"[{self.time_s!r}, {t_end!r}]"
                )
        return self._advance(t_end, samples)

    def _advance(self, t_end: float, samples: F64) -> SimulationResult:
        """:meth:`advance` on checked arguments (finite ``t_end`` >= the simulator time; finite,
        sorted, contiguous float64 ``samples`` inside the chunk)."""
        n, N = samples.size, len(self._specs)
        t_start = self.time_s
        march = self._params.coupling == "one_way" and self._march_pays(t_end - t_start)
        out_cx, out_cv, out_ca, out_cb, out_px, out_pv, out_pp = _output_arrays(n, N, march)
        seg = self._drive.segments()
        self._state[layout.S_SEG] = seg.index_at(self.time_s)
        chunks: list[EventArrays] = []
        # events already due: drive changes at the chunk's start, and a logged drive change
        # exactly at its end (the kernel stops before it)
        pending = list(self._pending_events)
        k_end = seg.index_at(t_end)
        if t_end > t_start and seg.start_s[k_end] == t_end and seg.logged[k_end]:
            pending.append((t_end, int(EventKind.DRIVE_CHANGE), -1))
        if pending:
            pt, pk, pp = zip(*pending, strict=True)
            chunks.append((np.array(pt), np.array(pk, np.int8), np.array(pp, np.int64)))
        log: list[EventArrays | Callable[[], EventArrays]] = []
        if march:
            # carrier alone first (pieces recorded), then every group along it, in parallel;
            # the part arrays are column-major there (each group writes its own columns)
            no_groups, no_members = _Groups.empty(), _Members.empty()
            pieces = self._run_kernel(
                t_end,
                samples,
                (out_cx, out_cv, out_ca, out_cb),
                no_groups,
                no_members,
                chunks,
                record=True,
            )
            log = self._run_groups(
                pieces, t_end, samples, out_cx, out_cv, out_px, out_pv, out_pp, chunks
            )
            if self._g.has_duplicate_sticking():
                self._regroup()  # parts of one friction that stick together share a future
        else:
            self._run_kernel(
                t_end,
                samples,
                (out_cx, out_cv, out_ca, out_cb, out_px, out_pv, out_pp),
                self._g,
                self._m,
                chunks,
                record=False,
            )
            log.extend(chunks)
        self._pending_events = []
        return SimulationResult(
            t_s=samples,
            carrier_x_m=out_cx,
            carrier_v_mps=out_cv,
            carrier_a_mps2=out_ca,
            branch=out_cb,
            part_x_m=out_px,
            part_v_mps=out_pv,
            part_phase=out_pp,
            events=EventLog(log),
            **self._totals(),
        )

    #: one-way runs with at least this many distinct groups march the groups in parallel ...
    parallel_min_groups: int = 4
    #: ... when the chunk is long enough: ``duration_s * groups**2`` at least this [s]. The march
    #: costs about 0.1-0.2 ms per call before it starts; the global loop's cost per simulated
    #: second grows with the square of the group count. The crossover (``bench_physics.py``,
    #: "Global event loop or group march"; it moves with the event rate) lies between 1 and 10 s
    #: of run for 4 groups, 0.1 and 1 s for 8 and 16, below 0.1 s for 32. A live simulator's
    #: ticks stay in the global loop.
    march_min_work_s: float = 32.0
    #: carrier pieces per parallel group pass (bounds the event buffers)
    pieces_per_pass: int = 512

    def _march_pays(self, duration_s: float) -> bool:
        """Whether the group march is worth its start-up for a chunk of ``duration_s``."""
        if self._g.size < self.parallel_min_groups:
            return False
        groups = int(np.count_nonzero(self._g.head >= 0))
        return (
            groups >= self.parallel_min_groups and duration_s * groups**2 >= self.march_min_work_s
        )

    def _run_kernel(
        self,
        t_end: float,
        samples: F64,
        outs: tuple[npt.NDArray[Any], ...],
        g: _Groups,
        m: _Members,
        chunks: list[tuple[F64, I8, I64]],
        record: bool,
    ) -> F64:
        """The event loop of carrier and groups (global kernel); returns the recorded pieces."""
        n = samples.size
        if len(outs) == 4:
            outs = (*outs, np.empty((n, 0)), np.empty((n, 0)), np.empty((n, 0), np.int8))
        seg = self._drive.segments()
        cap = 1024 + 8 * (m.size + 1)
        ev_t, ev_kind, ev_part = np.empty(cap), np.empty(cap, np.int8), np.empty(cap, np.int64)
        piece_cap = min(64 + int(400 * (t_end - self.time_s)), 1 << 16) if record else 0
        pieces = np.empty((piece_cap, recorded_pieces.PIECE_WIDTH))
        piece_chunks: list[F64] = []
        counters = np.zeros(5, np.int64)
        self._counters = counters
        while True:
            status = global_loop.advance(  # type: ignore[call-arg]
                self._model,
                seg.start_s,
                seg.omega_rad_s,
                seg.amplitude_n,
                seg.phase_rad,
                seg.logged,
                self._state,
                g.L,
                g.D,
                g.mass,
                g.u,
                g.y,
                g.slip,
                g.lead,
                g.phase,
                g.head,
                m.group,
                m.next,
                m.offset,
                m.mass,
                m.slip0,
                m.exit_t,
                t_end,
                samples,
                *outs,
                ev_t,
                ev_kind,
                ev_part,
                counters,
                pieces,
            )
            k = int(counters[1])
            chunks.append((ev_t[:k].copy(), ev_kind[:k].copy(), ev_part[:k].copy()))
            counters[1] = 0
            if record:
                piece_chunks.append(pieces[: int(counters[4])].copy())
                counters[4] = 0
            if status == layout.STATUS_BUFFER_FULL:
                if k == 0:
                    cap *= 2
                    ev_t, ev_kind, ev_part = (
                        np.empty(cap),
                        np.empty(cap, np.int8),
                        np.empty(cap, np.int64),
                    )
                continue
            if status != layout.STATUS_DONE:
                reason = _status_reason(status)
                raise SimulationError(f"sharp solver stopped at t={self.time_s!r} s: {reason}")
            break
        if not record:
            return np.empty((0, recorded_pieces.PIECE_WIDTH))
        return np.concatenate(piece_chunks) if piece_chunks else pieces[:0]

    def _run_groups(
        self,
        pieces: F64,
        t_end: float,
        samples: F64,
        out_cx: F64,
        out_cv: F64,
        out_px: F64,
        out_pv: F64,
        out_pp: I8,
        earlier: list[EventArrays],
    ) -> list[EventArrays | Callable[[], EventArrays]]:
        """March every group along the recorded carrier pieces (one-way coupling), in parallel.

        Returns the run's events, one chunk per pass in time order, the chunks one after the
        other: each pass's events with those of ``earlier`` (the drive's and the carrier's, in
        input order before the groups') up to the pass's end. A pass's chunk is a function that
        puts them in order (:class:`EventLog` calls it when the events are first read)."""
        g, m = self._g, self._m
        G = g.size
        track = float(self._model[layout.TRACK])
        pre_t = np.concatenate([c[0] for c in earlier]) if earlier else np.zeros(0)
        pre_kind = np.concatenate([c[1] for c in earlier]) if earlier else np.zeros(0, np.int8)
        pre_part = np.concatenate([c[2] for c in earlier]) if earlier else np.zeros(0, np.int64)
        pre_left = np.ones(pre_t.size, bool)
        chunks: list[EventArrays | Callable[[], EventArrays]] = []
        n_total = pieces.shape[0]
        for k0 in range(0, max(n_total, 1), self.pieces_per_pass):
            batch = np.ascontiguousarray(pieces[k0 : k0 + self.pieces_per_pass])
            nb = batch.shape[0]
            tables = recorded_pieces.piece_tables(batch, nb)  # shared by every group of the pass
            final = k0 + nb >= n_total
            t_stop = t_end if final else float(pieces[k0 + nb, recorded_pieces.P_T0])
            ns0 = (
                int(np.searchsorted(samples, batch[0, recorded_pieces.P_T0], side="left"))
                if nb
                else 0
            )
            members_before = m.group.copy()
            saved = (g.copy(), m.copy())
            cap = 16 + 4 * nb
            # small passes run on one thread: a parallel region costs more than it saves
            # there (and OpenMP's spin-waiting is slow on a loaded machine)
            serial = G * nb < SMALL_PARALLEL_WORK
            with _one_thread_if(serial):
                while True:
                    ev_t = np.empty((G, cap))
                    ev_kind = np.empty((G, cap), np.int8)
                    ev_part = np.empty((G, cap), np.int64)
                    ev_n = np.zeros(G, np.int64)
                    status = np.full(G, -1, np.int64)
                    group_march.advance_groups(  # type: ignore[call-arg]
                        batch, nb, *tables, track, t_stop, samples, ns0, out_cx, out_cv,
                        g.L, g.D, g.mass, g.u, g.y, g.slip, g.lead, g.phase, g.head,
                        m.group, m.next, m.offset, m.mass, m.slip0, m.exit_t,
                        out_px, out_pv, out_pp, ev_t, ev_kind, ev_part, ev_n, status,
                    )  # fmt: skip
                    if np.any(status[saved[0].head >= 0] == layout.STATUS_BUFFER_FULL):
                        g.restore(saved[0])
                        m.restore(saved[1])
                        cap *= 2
                        continue
                    bad = np.flatnonzero((status != layout.STATUS_DONE) & (status != -1))
                    if bad.size:
                        raise SimulationError(
                            f"sharp solver (groups {bad.tolist()}) stopped: an event repeats "
                            "at one instant without progress"
                        )
                    break
            # the earlier events up to the pass's end (ties at the end: before the groups')
            take = pre_left.copy() if final else pre_left & (pre_t <= t_stop)
            pre_left &= ~take
            # in order when first read; every argument is this pass's own copy (exit times as
            # they are now: later passes and advances only add exits after this pass)
            order_pass = functools.partial(
                _pass_events_in_time_order, serial,
                pre_t[take], pre_kind[take], pre_part[take],
                ev_t, ev_kind, ev_part, ev_n, members_before, m.exit_t.copy(),
            )  # fmt: skip
            chunks.append(order_pass)
            if final:
                break
        return chunks

    def track_positions(self) -> F64:
        """Every part's track position now (its lab position less the carrier's), NaN for parts
        that left the track; no event, no change of state."""
        totals = self._totals()
        track = totals["part_end_x_m"] - float(self._state[layout.S_X])
        return np.where(np.isnan(totals["part_exit_t_s"]), track, np.nan)

    def _totals(self) -> dict[str, F64]:
        m, g = self._m, self._g
        N = m.size
        start_t, start_x, end_t, end_x, slip, exit_t = sampling.part_totals(
            m.group[:N], m.offset, m.slip0, m.exit_t, m.start_t, m.start_x, g.y, g.slip,
            self.time_s, float(self._state[layout.S_X]),
        )  # fmt: skip
        return {
            "part_start_t_s": start_t,
            "part_start_x_m": start_x,
            "part_end_t_s": end_t,
            "part_end_x_m": end_x,
            "part_slip_time_s": slip,
            "part_exit_t_s": exit_t,
        }


@contextlib.contextmanager
def limited_threads(count: int) -> Iterator[None]:
    """numba's parallel kernels (the group passes, :func:`simulate_many`) on at most ``count``
    threads inside the block; the thread count is restored after it.

    For a caller that shares the machine with live work: a node computing a table at configure
    leaves a core to the nodes beside it. ``count`` above the current count changes nothing.
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"thread count must be an integer of at least 1, got {count!r}")
    threads = numba.get_num_threads()
    numba.set_num_threads(min(count, threads))
    try:
        yield
    finally:
        numba.set_num_threads(threads)


def _one_thread_if(serial: bool) -> contextlib.AbstractContextManager[None]:
    """numba's parallel kernels on one thread inside the block if ``serial`` (a small group pass:
    see ``SMALL_PARALLEL_WORK``)."""
    return limited_threads(1) if serial else contextlib.nullcontext()


def _pass_events_in_time_order(serial: bool, *arrays: npt.NDArray[Any]) -> EventArrays:
    """:func:`~feeder_ros.physics.exact.ordering.group_events_in_time_order` of one group pass, on
    one thread if the pass ran on one."""
    with _one_thread_if(serial):
        return ordering.group_events_in_time_order(*arrays)


def _status_reason(status: int) -> str:
    """Why the sharp solver stopped, from its status code."""
    return {
        layout.STATUS_RESONANCE: "exact resonance of an undamped branch (c = 0, drive frequency "
        "equal to a branch natural frequency): no bounded closed form",
        layout.STATUS_STUCK: "an event repeats at one instant without progress",
        layout.STATUS_BUFFER_FULL: "the event buffer filled",
    }.get(status, f"status {status}")
