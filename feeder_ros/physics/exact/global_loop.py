"""The global event loop, :func:`advance`: the carrier and every part group in one loop, for any
coupling (the paper's Fig. 6, generalised to many parts and both switch modes).

At each stop the stepping skips the functions proven positive well beyond it (``f_skip``: the
release offset, or the end of a safe step reaching more than 8 steps ahead). With one-way coupling
a part event does not change the carrier, so :func:`advance` continues the same closed-form piece
after it (the part's polynomials are then written in the time since the event) instead of
restarting the carrier.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit

from feeder_ros.physics.exact.closed_form import (
    SHIFT_CHAIN,
    _basis,
    _basis_all,
    _basis_at,
    _branch_of_piece,
    _fill_rows,
    _row,
    _row_bound,
    _shift_basis,
)
from feeder_ros.physics.exact.event_steps import (
    _carrier_event,
    _carrier_functions,
    _count_repeat,
    _end_group,
    _exit_lead,
    _group_functions,
    _log,
    _log_group,
    _merge_into_sticking_group,
    _new_phase,
)
from feeder_ros.physics.exact.layout import (
    COUPLING,
    DAMPING,
    EPS,
    EV_DRIVE,
    EV_EXIT,
    EV_REVERSAL,
    EV_SLIP_START,
    EV_STICK,
    F_EXIT,
    F_RELVEL,
    F_SLIDE_BWD,
    F_STICK_DOWN,
    F_STICK_UP,
    K_BWD,
    K_FWD,
    LOG_EVENTS,
    M_BASE,
    M_ONEWAY,
    N_ROT,
    S_MODE,
    S_SEG,
    S_T,
    S_V,
    S_X,
    SLIP_BACKWARD,
    STATUS_BUFFER_FULL,
    STATUS_DONE,
    STATUS_RESONANCE,
    STATUS_STUCK,
    STICK,
    SWITCH,
    TRACK,
)
from feeder_ros.physics.exact.recorded_pieces import _record_piece
from feeder_ros.physics.exact.records import Groups, Members, ShiftTable
from feeder_ros.physics.exact.sampling import _piece_samples
from feeder_ros.physics.exact.search import (
    REL_FREE,
    REL_NEVER,
    REL_NOW,
    _bound_of_row,
    _bound_terms,
    _certified_step,
    _clearly_free,
    _release,
    _safe_step,
    search_scratch,
)


@njit(cache=True)
def advance(
    model, d_start, d_omega, d_amp, d_phase, d_logged, state, g_L, g_D, g_mass, g_u, g_y, g_slip,
    g_lead, g_phase, g_head, m_group, m_next, m_o, m_mass, m_slip0, m_exit_t, t_end, samples,
    out_cx, out_cv, out_ca, out_cb, out_px, out_pv, out_pp, ev_t, ev_kind, ev_part, counters,
    pieces,
):  # fmt: skip
    """Advance the carrier and all part groups from ``state[S_T]`` to ``t_end`` (in place).

    ``counters`` = [samples written, events written, status, safe steps taken (diagnostic),
    pieces recorded]. If ``pieces`` has rows, every closed-form piece of the carrier is recorded
    there (see :func:`_record_piece`) for :func:`advance_groups`.
    Samples ``samples[counters[0]:]`` with
    time < the end of the run (<= ``t_end`` for the last piece) are written. Returns the status:
    0 done, 1 event buffer full (state saved at the event time; call again with room), 2 exact
    resonance of an undamped branch, 3 stuck (an event repeated at one instant without progress).
    """
    rows, fn, bound_rows, der = search_scratch(4 + 2 * g_L.shape[0])
    shift_table = ShiftTable(np.full((2, 3), np.nan), np.zeros((2, 4, N_ROT)), np.ones(2, np.int64))
    return _event_loop(
        model, d_start, d_omega, d_amp, d_phase, d_logged, state, g_L, g_D, g_mass, g_u, g_y,
        g_slip, g_lead, g_phase, g_head, m_group, m_next, m_o, m_mass, m_slip0, m_exit_t, t_end,
        samples, out_cx, out_cv, out_ca, out_cb, out_px, out_pv, out_pp, ev_t, ev_kind, ev_part,
        counters, pieces, (rows, fn, bound_rows, der, shift_table),
    )  # fmt: skip


# _nrt=False: no reference counting in the loop (numba counts a reference for every array it
# hands to an inlined step, which cost the loop up to 1.7x). Safe because every array here is
# owned by the caller (advance, or the simulator) for the whole call, and numba refuses to
# compile an allocation without its runtime; numba is pinned (distros/*/constraints.txt).
@njit(cache=True, _nrt=False)  # type: ignore[call-overload]  # numba-internal option
def _event_loop(
    model, d_start, d_omega, d_amp, d_phase, d_logged, state, g_L, g_D, g_mass, g_u, g_y, g_slip,
    g_lead, g_phase, g_head, m_group, m_next, m_o, m_mass, m_slip0, m_exit_t, t_end, samples,
    out_cx, out_cv, out_ca, out_cb, out_px, out_pv, out_pp, ev_t, ev_kind, ev_part, counters,
    pieces,
    scratch,
):  # fmt: skip
    """The body of :func:`advance`, with its scratch arrays (``rows``, the event functions, the
    search's bound rows, the release's derivatives, the sample shift table) made by it."""
    rows, fn, bound_rows, der, shift_table = scratch
    n_members = m_group.shape[0]
    n_samples = samples.shape[0]
    switch = int(model[SWITCH])
    two_way = model[COUPLING] != 0.0
    log_events = model[LOG_EVENTS] != 0.0
    c = model[DAMPING]
    kf = model[K_FWD]
    kb = model[K_BWD]
    track = model[TRACK]
    cap = ev_t.shape[0]

    zero_count = 0
    # output samples: the basis is shifted by the nominal spacing h_nom between samples
    h_nom = 0.0
    if n_samples >= 2:
        h_nom = (samples[n_samples - 1] - samples[0]) / (n_samples - 1)
    carrier_out = (out_cx, out_cv, out_ca, out_cb)
    groups = Groups(g_L, g_D, g_mass, g_u, g_y, g_slip, g_lead, g_phase, g_head)
    members = Members(m_group, m_next, m_o, m_mass, m_slip0, m_exit_t)
    log_buffer = (ev_t, ev_kind, ev_part, counters)
    drive = (d_start, d_omega, d_amp, d_phase, d_logged)
    parts_out = (out_px, out_pv, out_pp)

    record = pieces.shape[0] > 0
    # a part event with one-way coupling leaves the carrier's closed form as it is: the loop then
    # continues the same piece from the event's local time ts (cont) instead of restarting it
    cont = False
    ts = 0.0
    xs = 0.0
    vs = 0.0
    # the last directly evaluated sample: its local time, the shifts since, its basis
    base = (0.0, N_ROT, 1.0, 0.0, 0.0, 1.0)
    # the piece's values, set at its start (typed here for numba)
    n_cf = seg = 0
    t0 = A = piece_end = T = F0 = k = 0.0
    mode = m = 1.0
    drive_end = held = False
    piece = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # sigma, lam, root, r1, w, phi
    shift = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # the piece's coefficients of _shift_basis
    shift_max = 0.0
    e_basis = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # the basis (and bounds) at the last event
    chain = e_chain = 0  # shifts since the basis (at the last event) was evaluated directly
    while True:
        if not cont:
            t0 = state[S_T]
            if t0 >= t_end:
                break
        if (log_events and counters[1] + n_members + 3 > cap) or (
            record and counters[4] + 1 > pieces.shape[0]
        ):
            counters[2] = STATUS_BUFFER_FULL
            return STATUS_BUFFER_FULL
        if not cont:
            ts = 0.0
            xs = state[S_X]
            vs = state[S_V]
            mode = state[S_MODE]
            held = mode == 0.0
            seg, w, A, phi, piece_end, drive_end = _drive_segment(
                state, t0, t_end, drive, log_events, log_buffer
            )
            T = piece_end - t0
            m, F0 = _carrier_load(model, two_way, groups)
            k = kf if mode >= 0.0 else kb
            piece, shift, shift_max = _branch_of_piece(c, m, k, w, phi)
            if not _fill_rows(rows, piece, A, m, c, k, F0, xs, vs, held):
                counters[2] = STATUS_RESONANCE
                return STATUS_RESONANCE

        # ---- event functions of this piece
        # (the carrier's functions keep their state when the piece continues after a part event)
        if not cont:
            n_cf = _carrier_functions(held, switch, mode, F0, kf, kb, xs, fn)
        nf, lmin = _group_functions(n_cf, vs, xs, track, groups, fn)

        # ---- release functions that start on (or across) their zero (at ts; the part's
        # polynomials are in s = tau - ts)
        chain = 0
        if ts == 0.0 or not cont:
            basis = _basis_at(ts, piece)
        else:
            # after a part event: the basis at the event (the stop that found it)
            basis = e_basis
            chain = e_chain
        hit = _release_global(rows, fn, n_cf if cont else 0, nf, ts, T, basis, lmin, der)
        tau_e = ts if hit >= 0 else T
        e_basis = basis
        e_chain = chain
        if hit < 0:
            # ---- safe stepping to the first root
            hit, tau_e, e_basis, e_chain = _search_global(
                rows, fn, nf, t0, ts, T, held, piece, shift, shift_max, basis, chain, bound_rows,
                counters,
            )  # fmt: skip

        # ---- samples in [t0, t0 + tau_e)  (the last piece of the run includes t_end)
        base = _piece_samples(
            samples, counters, t0, ts, xs, t0 + tau_e, hit < 0 and not drive_end, t_end, h_nom,
            base if cont else (0.0, N_ROT, 1.0, 0.0, 0.0, 1.0), piece, rows, held, mode,
            shift_table, carrier_out, groups, members, parts_out,
        )  # fmt: skip

        # ---- state at the end of the piece
        xe, ve, ae, Fe, dFe = _end_of_piece(
            rows, piece, A, held, mode, t0, ts, xs, tau_e, hit >= 0, e_basis, groups, pieces,
            counters,
        )  # fmt: skip
        te = t0 + tau_e
        state[S_T] = te
        state[S_X] = xe
        state[S_V] = ve
        cont = False
        if hit < 0:
            if drive_end:
                state[S_T] = piece_end
                state[S_SEG] = seg + 1
                if log_events and d_logged[seg + 1] != 0:
                    _log(ev_t, ev_kind, ev_part, counters, piece_end, EV_DRIVE, -1)
                continue
            state[S_T] = t_end
            break

        # ---- one event at te (exits always progress: they do not count as repeats)
        zero_count, stuck = _count_repeat(zero_count, tau_e == ts, fn.kind[hit])
        if stuck:
            counters[2] = STATUS_STUCK
            return STATUS_STUCK
        kind = fn.kind[hit]
        _event_at(
            kind, fn.group[hit], te, (xe, ve, ae, Fe, dFe), (switch, mode, F0, m, c, k, kf, kb),
            two_way and not held, lmin, state, groups, members, log_buffer, log_events,
        )  # fmt: skip
        if not two_way and not record and kind >= F_STICK_UP:
            # a part event: the carrier's piece goes on from here
            cont = True
            ts = tau_e
            xs = xe
            vs = ve
    counters[2] = STATUS_DONE
    return STATUS_DONE


@njit(cache=True, inline="always")
def _drive_segment(state, t0, t_end, drive, log_events, log):
    """The drive segment of a piece starting at ``t0`` (kept in ``state[S_SEG]``; ``drive`` =
    the segments' start times, rates, amplitudes, phases and logged flags): its index, the
    drive's rate, amplitude and phase at ``t0``, and where the drive ends the piece, with True
    (the next change, before ``t_end``) or False (``t_end``). A change the start has passed (the
    last piece ended on an event within round-off of it, its end time rounded onto the change)
    is logged here."""
    d_start, d_omega, d_amp, d_phase, d_logged = drive
    ev_t, ev_kind, ev_part, counters = log
    seg = int(state[S_SEG])
    nseg = d_start.shape[0]
    while seg + 1 < nseg and d_start[seg + 1] <= t0:
        seg += 1
        if log_events and d_logged[seg] != 0:
            _log(ev_t, ev_kind, ev_part, counters, d_start[seg], EV_DRIVE, -1)
    state[S_SEG] = seg
    w = d_omega[seg]
    A = d_amp[seg]
    phi = np.fmod(d_phase[seg] + w * (t0 - d_start[seg]), 2.0 * math.pi)
    if seg + 1 < nseg and d_start[seg + 1] < t_end:
        return seg, w, A, phi, d_start[seg + 1], True
    return seg, w, A, phi, t_end, False


@njit(cache=True, inline="always")
def _carrier_load(model, two_way, gr):
    """The carrier's mass and the parts' constant force on it over the next piece. With two-way
    coupling the sticking groups ride on the carrier (their mass is added) and each slipping
    group pulls with its kinetic friction force (``-+mass*D``); with one-way coupling the model's
    mass (parts included) and no force."""
    g_L, g_D, g_mass, _g_u, _g_y, _g_slip, _g_lead, g_phase, g_head = gr
    if not two_way:
        return model[M_ONEWAY], 0.0
    m = model[M_BASE]
    F0 = 0.0
    for g in range(g_L.shape[0]):
        if g_head[g] < 0:
            continue
        if g_phase[g] == STICK:
            m += g_mass[g]
        elif g_phase[g] == SLIP_BACKWARD:
            F0 -= g_mass[g] * g_D[g]
        else:
            F0 += g_mass[g] * g_D[g]
    return m, F0


@njit(cache=True, inline="always")
def _release_global(rows, fn, first, nf, ts, T, basis, lmin, der):
    """Release the functions ``first .. nf-1`` at the sub-piece's start ``ts`` (:func:`_release`):
    each gets the time up to which it is provably positive (``fn.skip``) or is marked as having
    no root (``fn.zero``, also the stick limits when the carrier's acceleration stays below
    every sticking group's limit ``lmin`` for the whole piece). Returns the first function at or
    across its zero, moving out (an event at ``ts``), or -1."""
    f_kind, _f_group, f_row, f_sgn, f_c0, f_c1, f_c2, f_skip, f_zero, f_eval = fn
    cc, ss, sn, cs, bc, bs = basis
    stick_bound = _row_bound(rows, 2, bc, bs)
    for i in range(nf):
        f_eval[i] = False
    for i in range(first, nf):
        if _clearly_free(rows, f_row[i], f_sgn[i], f_c0[i], f_c1[i], cc, ss, sn, cs, bc, bs):
            code, s_rel = REL_FREE, 0.0
        else:
            code, s_rel = _release(
                rows, f_row[i], f_sgn[i], f_c0[i], f_c1[i], f_c2[i], T - ts, cc, ss, sn, cs, bc,
                bs, der,
            )  # fmt: skip
        f_skip[i] = ts + s_rel
        f_zero[i] = code == REL_NEVER
        if code == REL_NOW:
            return i
        if (f_kind[i] == F_STICK_UP or f_kind[i] == F_STICK_DOWN) and stick_bound < lmin:
            f_zero[i] = True  # |a| stays below every stick limit for the whole piece
    return -1


@njit(cache=True, inline="always")
def _search_global(
    rows, fn, nf, t0, ts, T, held, piece, shift, shift_max, basis, chain, br, counters
):  # fmt: skip
    """Certified safe steps (:mod:`.search`) from ``ts`` to the first root of the functions
    ``0 .. nf-1`` on the piece ``[0, T)``. Each stop takes a safe step only for the functions
    whose provably positive interval ends there (the longer of the certified step and a second
    lower bound that takes the drive's sinusoid at its worst); a short step takes the basis by
    an exact shift from the last stop. Returns the function hit (-1: none, the piece runs to
    ``T``), the time of the root (or ``T``), and the basis there with its shift chain (those at
    ``ts`` if none). ``counters[3]`` counts the stops."""
    # the records' arrays as locals: numba counts a reference per field read otherwise
    _f_kind, _f_group, f_row, f_sgn, f_c0, f_c1, f_c2, f_skip, f_zero, f_eval = fn
    vals, bnds, hbnds, r_amp = br.vals, br.bnds, br.hbnds, br.amp
    sigma, lam, root, r1, w, phi = piece
    a2, a3, a4, a5, b3, b4, b5 = shift
    cc, ss, sn, cs, bc, bs = basis
    chain0 = chain
    # per-row bound pieces: |alpha|, |beta|, amplitude form (under-damped), sinusoid, constant;
    # only the rows the functions need: value up to r + 2, bound up to r + 3
    lo = 6 if held else 0
    hi_r = 10 if held else 0
    if not held:
        for i in range(nf):
            if not f_zero[i] and f_row[i] + 4 > hi_r:
                hi_r = f_row[i] + 4
    _bound_terms(rows, lo, hi_r, lam, root, br.abs_a, br.abs_b, r_amp, br.R)
    tau = ts
    for r in range(6):
        vals[r] = 0.0
        bnds[r] = 0.0
    # undamped: the basis bounds (1, 1/root) and so the row bounds are constant
    const_bounds = sigma == 0.0 and lam < 0.0
    at_ts = True  # the first stop is ts, whose basis values are those of the release
    tau_b = ts  # where the basis values were taken
    new_bounds = True  # bc, bs changed since the row bounds were formed
    while True:
        if not at_ts:
            if tau - tau_b <= shift_max and chain < SHIFT_CHAIN:
                # a short step (near a root): the basis shifted from the last stop; its
                # bounds over [tau_b, inf) hold over [tau, inf) too
                cc, ss, sn, cs = _shift_basis(
                    tau - tau_b, a2, a3, a4, a5, b3, b4, b5, sigma, lam, w, cc, ss, sn, cs
                )
                chain += 1
            else:
                cc, ss, sn, cs, bc, bs = _basis_all(tau, sigma, lam, root, r1, w, phi)
                chain = 0
                new_bounds = not const_bounds
            tau_b = tau
        at_ts = False
        if held:
            vals[0] = rows[0, 4]
            bnds[0] = abs(rows[0, 4])
        for r in range(lo, hi_r):
            vals[r] = _row(rows, r, cc, ss, sn, cs)
        if new_bounds:
            new_bounds = False
            for r in range(lo, hi_r):
                hb, bt = _bound_of_row(rows, r, bc, bs, br.abs_a, br.abs_b, r_amp, br.R)
                hbnds[r] = hb
                bnds[r] = bt
        t_res = 8.0 * EPS * (abs(t0) + tau + 1e-3)
        # the next stop: each function is provably positive before f_skip[i] (its release
        # offset, or the end of its last safe step), so only the functions whose interval
        # ends here are evaluated again
        t_next = T
        for i in range(nf):
            if f_zero[i]:
                continue
            if tau < f_skip[i]:
                if f_skip[i] < t_next:
                    t_next = f_skip[i]
                continue
            r = f_row[i]
            sg = f_sgn[i]
            sp = tau - ts
            poly = f_c0[i] + sp * (f_c1[i] + sp * f_c2[i])
            f = sg * vals[r] + poly
            h1, d = _certified_step(
                f, sp, sg, f_c0[i], f_c1[i], f_c2[i], r, vals, bnds, t_next - tau
            )
            if h1 < 0.0:
                return i, tau, (cc, ss, sn, cs, bc, bs), chain
            if h1 < t_next - tau and not held:
                # second lower bound: the drive's sinusoid at its worst, the homogeneous
                # terms with their own (slower) curvature bound
                asg = abs(sg)
                g = f - sg * (rows[r, 2] * sn + rows[r, 3] * cs) - asg * r_amp[r]
                if g > 0.0:
                    dh = d - sg * (rows[r + 1, 2] * sn + rows[r + 1, 3] * cs)
                    h_alt = _safe_step(g, dh, asg * hbnds[r + 2] + 2.0 * abs(f_c2[i]))
                    if h_alt > h1:
                        h1 = h_alt if h_alt < t_next - tau else t_next - tau
            if h1 <= t_res:
                return i, tau, (cc, ss, sn, cs, bc, bs), chain
            f_skip[i] = tau + h1
            f_eval[i] = True
            if f_skip[i] < t_next:
                t_next = f_skip[i]
        if t_next >= T:
            return -1, T, basis, chain0
        # a function whose interval ends soon is evaluated again at the next stop anyway
        # (a fresh step from there is usually longer than the rest of the old one)
        t_near = tau + 8.0 * (t_next - tau)
        for i in range(nf):
            if f_eval[i]:
                f_eval[i] = False
                if f_skip[i] < t_near:
                    f_skip[i] = 0.0
        tau = t_next
        counters[3] += 1


@njit(cache=True, inline="always")
def _event_at(kind, g, te, end, branch, coupled, lmin, state, gr, mb, log, log_events):
    """The event ``kind`` at ``te`` (group ``g``'s, if a part's), the carrier's end of piece
    there ``end`` = (x, v, a, F, dF) on ``branch`` = (switch mode, its mode, F0, m, c, k, kf,
    kb): the carrier's own (a stiffness branch or the end of a sliding hold; its new state in
    ``state``) or a part's (:func:`_part_event`). Logged to ``log`` when ``log_events``."""
    xe, ve, ae, Fe, dFe = end
    switch, mode, F0, m, c, k, kf, kb = branch
    if kind <= F_SLIDE_BWD:
        state[S_X], state[S_V], state[S_MODE], ev = _carrier_event(
            kind, switch, mode, xe, ve, Fe, dFe, F0, m, kf, kb
        )
        if ev >= 0 and log_events:
            ev_t, ev_kind, ev_part, counters = log
            _log(ev_t, ev_kind, ev_part, counters, te, ev, -1)
    else:
        carrier = (xe, ve, ae, Fe, F0, c, k, m)
        _part_event(kind, g, te, carrier, coupled, lmin, gr, mb, log, log_events)


@njit(cache=True, inline="always")
def _part_event(kind, g, te, carrier, coupled, lmin, gr, mb, log, log_events):
    """A part event at ``te``, the carrier at ``carrier`` = (x, v, a, F, F0, c, k, m) there
    (``coupled``: two-way coupling, not held). At a stick limit (F_STICK_UP, F_STICK_DOWN) every
    sticking group whose limit ``L`` the carrier's acceleration exceeds (``lmin`` at least)
    starts slipping with the carrier's velocity. Where group ``g``'s relative velocity vanishes
    (F_RELVEL) it sticks (and merges with a sticking group of the same friction) if the
    carrier's acceleration with the group on it is within its limit, else it reverses. At the
    track end (F_EXIT) group ``g``'s lead part leaves. Logged to ``log`` = (t, kind, part,
    counters) when ``log_events``."""
    g_L, g_D, g_mass, g_u, g_y, g_slip, g_lead, g_phase, g_head = gr
    m_group, m_next, m_o, m_mass, m_slip0, m_exit_t = mb
    ev_t, ev_kind, ev_part, counters = log
    xe, ve, ae, Fe, F0, c, k, m = carrier
    if kind in (F_STICK_UP, F_STICK_DOWN):
        new_phase = _new_phase(kind, 0.0, 0.0)
        limit = max(abs(ae), lmin) * (1.0 + 1e-12)
        for h in range(g_L.shape[0]):
            if g_head[h] >= 0 and g_phase[h] == STICK and g_L[h] <= limit:
                g_phase[h] = new_phase
                g_u[h] = ve
                if log_events:
                    _log_group(
                        ev_t, ev_kind, ev_part, counters, te, EV_SLIP_START, h, g_head, m_next
                    )
    elif kind == F_RELVEL:
        g_u[g] = ve
        a_test = ae
        if coupled:
            # carrier acceleration with this group stuck to it
            Fs = F0 + (g_mass[g] * g_D[g] if g_phase[g] == SLIP_BACKWARD else -g_mass[g] * g_D[g])
            a_test = (Fe + Fs - c * ve - k * xe) / (m + g_mass[g])
        g_phase[g] = _new_phase(kind, a_test, g_L[g])
        if g_phase[g] == STICK:
            if log_events:
                _log_group(ev_t, ev_kind, ev_part, counters, te, EV_STICK, g, g_head, m_next)
            _merge_into_sticking_group(
                g, g_head, g_phase, g_L, g_D, g_y, g_slip, g_mass, g_lead, m_group,
                m_next, m_o, m_slip0,
            )  # fmt: skip
        elif log_events:
            _log_group(ev_t, ev_kind, ev_part, counters, te, EV_REVERSAL, g, g_head, m_next)
    elif kind == F_EXIT:
        lead_i = _exit_lead(
            g, te, xe, g_y, g_slip, g_mass, g_lead, g_head, m_group, m_next, m_o,
            m_mass, m_slip0, m_exit_t,
        )  # fmt: skip
        if log_events:
            _log(ev_t, ev_kind, ev_part, counters, te, EV_EXIT, lead_i)


@njit(cache=True, inline="always")
def _end_of_piece(
    rows, piece, A, held, mode, t0, ts, xs, tau_e, at_event, e_basis, gr, pieces, counters
):  # fmt: skip
    """The carrier's ``x, v, a``, drive force and its rate at the end ``tau_e`` of the piece
    (from ``e_basis``, the basis at the event that ends it when ``at_event``, else evaluated),
    with the groups brought there (:func:`_end_group`) and the piece recorded when the run
    records pieces (``pieces`` has rows; the loop checked the room) and it has a length."""
    g_L, g_D, _g_mass, g_u, g_y, g_slip, _g_lead, g_phase, g_head = gr
    sigma, lam, root, r1, w, phi = piece
    if at_event:
        cc, ss, sn, cs, _, _ = e_basis
    else:
        cc, ss, sn, cs = _basis(tau_e, sigma, lam, root, r1, w, phi)
    xe = _row(rows, 0, cc, ss, sn, cs)
    ve = 0.0 if held else _row(rows, 1, cc, ss, sn, cs)
    ae = 0.0 if held else _row(rows, 2, cc, ss, sn, cs)
    for g in range(g_L.shape[0]):
        if g_head[g] >= 0:
            _end_group(g, tau_e - ts, xs, xe, ve, g_phase, g_D, g_u, g_y, g_slip)
    if pieces.shape[0] > 0 and tau_e > 0.0:
        _record_piece(
            pieces, counters[4], t0, tau_e, sigma, lam, root, r1, w, phi, mode, rows, xe, ve, ae
        )
        counters[4] += 1
    return xe, ve, ae, A * sn, A * w * cs
