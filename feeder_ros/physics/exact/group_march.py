"""The group march, an accelerator for one-way coupling: the carrier's closed-form pieces are
recorded once by the global loop, then every group marches along them independently, in
parallel (:func:`advance_groups`).

Parts are handled in *groups*: parts with the same friction (``L = mu_s*g*kappa``, ``D =
mu_d*g*kappa``) that stick at the same time have identical velocity forever after, so a group
carries one velocity history; its members differ only by a track offset. With two-way coupling a
group also carries the summed mass of its members. :func:`advance` runs carrier and groups in one
event loop (any coupling); with one-way coupling :func:`advance` can instead record the carrier's
closed-form pieces, along which :func:`advance_groups` marches every group independently, in
parallel. There each piece is tabulated once for all groups (:func:`piece_tables`) and a group's
first roots are found on that table (:mod:`.node_table`); the certified search of :mod:`.search`
takes over only where the table does not decide.

:func:`_march_group` reads as the global loop's sub-piece cycle for one group: its functions, their
release, the table search, the certified search, samples, the end of the sub-piece and its event.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import numpy as np
from numba import njit, prange

from feeder_ros.physics.exact.closed_form import _basis_all, _row, _row_bound
from feeder_ros.physics.exact.event_steps import (
    _count_repeat,
    _end_group,
    _exit_lead,
    _new_phase,
    _slip_functions,
    _stick_functions,
)
from feeder_ros.physics.exact.layout import (
    EPS,
    EV_EXIT,
    EV_REVERSAL,
    EV_SLIP_START,
    EV_STICK,
    EXITED,
    F_EXIT,
    F_RELVEL,
    F_STICK_DOWN,
    F_STICK_UP,
    SLIP_BACKWARD,
    SLIP_FORWARD,
    STATUS_BUFFER_FULL,
    STATUS_DONE,
    STATUS_STUCK,
    STICK,
)
from feeder_ros.physics.exact.node_table import _cell_root, _table_search, _table_tolerances
from feeder_ros.physics.exact.recorded_pieces import (
    BND_BC0,
    BND_BS0,
    BND_COS_PHI,
    BND_SIN_PHI,
    P_AE,
    P_VE,
    P_XE,
    _read_piece,
)
from feeder_ros.physics.exact.records import Groups, Members
from feeder_ros.physics.exact.search import (
    DERIVATIVE_ZERO,
    REL_FREE,
    REL_NEVER,
    REL_NOW,
    REL_SKIP,
    SPLIT_DEPTH,
    _bound_of_row,
    _bound_terms,
    _certified_step,
    _clearly_free,
    _release,
    search_scratch,
)


@njit(cache=True, parallel=True)
def advance_groups(
    pieces, n_pieces, node_start, node_h, tab, bnd, run_end, track, t_end, samples, ns0, out_cx,
    out_cv, g_L, g_D, g_mass, g_u, g_y, g_slip, g_lead, g_phase, g_head, m_group, m_next, m_o,
    m_mass, m_slip0, m_exit_t, out_px, out_pv, out_pp, ev_t, ev_kind, ev_part, ev_n, status,
):  # fmt: skip
    """All groups along recorded carrier pieces, in parallel (one-way coupling: independent).

    ``status[g]`` receives each group's status; a group stopped by a full event buffer (row ``g``)
    must be re-run with more room from a saved copy of its state.
    """
    recorded = (pieces, n_pieces, node_start, node_h, tab, bnd, run_end)
    groups = Groups(g_L, g_D, g_mass, g_u, g_y, g_slip, g_lead, g_phase, g_head)
    members = Members(m_group, m_next, m_o, m_mass, m_slip0, m_exit_t)
    outputs = (samples, ns0, out_cx, out_cv, out_px, out_pv, out_pp)
    events = (ev_t, ev_kind, ev_part, ev_n)
    for g in prange(g_L.shape[0]):
        if g_head[g] < 0 or status[g] == STATUS_DONE:
            continue
        status[g] = _march_group(
            g, recorded, track, t_end, groups, members, outputs, events, _march_scratch()
        )


@njit(cache=True)
def _march_scratch():
    """One group's scratch: the search's (:func:`search_scratch`, two functions) and the table
    search's stack of halved cells (right ends, and the row values there)."""
    rows, fn, bound_rows, der = search_scratch(2)
    return rows, fn, bound_rows, der, (np.zeros(SPLIT_DEPTH), np.zeros((SPLIT_DEPTH, 3)))


# _nrt=False: no reference counting (numba counts a reference for every array it hands to an
# inlined step). Safe because every array is owned by advance_groups' caller or made by
# _march_scratch for the whole call; numba refuses an allocation here (see global_loop._event_loop).
@njit(cache=True, _nrt=False)  # type: ignore[call-overload]  # numba-internal option
def _march_group(g, recorded, track, t_end, gr, mb, outputs, events, scratch):
    """One group of parts along the recorded carrier pieces (one-way coupling); returns a status.

    Group events go to row ``g`` of the event buffers with ``ev_part = -1`` (the caller expands
    them to the group's members), exits with the part index.
    """
    pieces, n_pieces, node_start, node_h, tab, bnd, run_end = recorded
    ev_t, _ev_kind, _ev_part, ev_n = events
    rows, fn, bound_rows, der, split_stack = scratch
    g_head = gr.head
    cap = ev_t.shape[1]
    L = gr.L[g]
    ns = outputs[1]
    zero_count = 0
    for k in range(n_pieces):
        t0, T, piece, held = _read_piece(pieces, k, rows)
        sigma, lam, root, r1, w, phi = piece
        bounds_ready = False  # the certified search's per-row bound data (set up when needed)
        last = k == n_pieces - 1
        base = node_start[k]
        nk = node_start[k + 1] - base
        ts = 0.0  # start of the current sub-piece (local time)
        at_ts = False  # the basis values are those at ts already (the last event's)
        basis = (1.0, 0.0, 0.0, 1.0, 1.0, 1.0)  # (typed here; set at the first pass, ts == 0)
        while True:
            if g_head[g] < 0:
                return STATUS_DONE  # the group is empty: nothing more to do
            if ev_n[g] + 2 > cap:
                return STATUS_BUFFER_FULL
            if ts == 0.0:
                # closed_form._basis_at(0.0, piece), stored once per piece by piece_tables
                basis = (
                    1.0, 0.0, bnd[k, BND_SIN_PHI], bnd[k, BND_COS_PHI], bnd[k, BND_BC0],
                    bnd[k, BND_BS0],
                )  # fmt: skip
            elif not at_ts:
                basis = _basis_all(ts, sigma, lam, root, r1, w, phi)
            at_ts = False
            rem = T - ts
            xs, ph, nf = _march_functions(g, rows, held, track, t0, T, rem, basis, gr, fn)
            hit, whole = _march_release(rows, fn, nf, ph, rem, nk, bnd, k, basis, der)
            s = 0.0
            certify = hit < 0 and nf > 0  # search with certified steps from s
            fresh = False  # the certified search starts with fresh basis values
            # (a function released for the whole rest of the piece, within round-off of zero all
            # along, goes to the certified search, which skips it as the global loop does)
            if certify and nk > 1 and rem > 0.0 and (ph != STICK or nf == 2) and not whole:
                nodes = (tab, run_end, base, nk, node_h[k], ts, T)
                solved, certify, fresh, s, hit, basis = _search_table(
                    pieces, k, nodes, fn, nf, ph, rem, rows, piece, t0, bnd, basis, split_stack
                )
                if not solved:
                    return STATUS_STUCK
            if certify:
                hit, s, basis, bounds_ready = _march_certified(
                    rows, fn, nf, ph, held, (t0, ts, rem), s, fresh, piece, basis, bound_rows,
                    der, bounds_ready,
                )  # fmt: skip
            tau_e = ts + s if hit >= 0 else T
            ns = _march_samples(
                outputs, ns, (t0, ts, xs), t0 + tau_e, last and hit < 0, t_end, ph, g, gr, mb
            )
            xe, ve, ae = _end_state(rows, held, hit >= 0, basis, pieces, k)
            se = tau_e - ts
            _end_group(g, se, xs, xe, ve, gr.phase, gr.D, gr.u, gr.y, gr.slip)
            if hit < 0:
                break
            at_ts = True  # the basis values are those at tau_e already
            zero_count, stuck = _count_repeat(zero_count, se == 0.0, fn.kind[hit])
            if stuck:
                return STATUS_STUCK
            _march_event(g, fn.kind[hit], t0 + tau_e, (xe, ve, ae), L, ns, gr, mb, outputs, events)
            ts = tau_e
    return STATUS_DONE


@njit(cache=True, inline="always")
def _march_functions(g, rows, held, track, t0, T, rem, basis, gr, fn):
    """The carrier at the sub-piece's start (``x``) and group ``g``'s phase and event functions
    there (slots 0 and 1): a sticking group's stick limits (or its track end, once past it), a
    slipping group's relative velocity and track end. Returns ``x``, the phase and the number of
    functions to search (0: none can have a root on the rest ``rem`` of the piece)."""
    _g_L, g_D, _g_mass, g_u, g_y, _g_slip, g_lead, g_phase, _g_head = gr
    f_kind, _f_group, f_row, f_sgn, f_c0, f_c1, f_c2, _f_skip, _f_zero, _f_eval = fn
    cc, ss, sn, cs, bc, bs = basis
    L = gr.L[g]
    xs = _row(rows, 0, cc, ss, sn, cs)
    vs = 0.0 if held else _row(rows, 1, cc, ss, sn, cs)
    ph = g_phase[g]
    if ph == STICK:
        g_u[g] = vs
    nf = 0
    if ph == STICK:
        _stick_functions(0, L, f_kind, f_row, f_sgn, f_c0, f_c1, f_c2)
        nf = 2
        if g_lead[g] + g_y[g] >= track:
            # a sticking part past the track end (put there, or the track shortened)
            f_kind[0] = F_EXIT
            f_sgn[0] = 0.0
            f_c0[0] = track - g_lead[g] - g_y[g]
            nf = 1
    else:
        _slip_functions(
            0, g, track, xs, g_phase, g_D, g_u, g_y, g_lead, f_kind, f_row, f_sgn, f_c0, f_c1,
            f_c2,
        )  # fmt: skip
        nf = 2
    if ph == STICK and nf == 2 and _row_bound(rows, 2, bc, bs) < L:
        nf = 0  # |a| stays below the stick limit for the rest of the piece
    if rem <= 4.0 * EPS * (abs(t0) + T):
        # an event within round-off of the end of the piece: the next piece (a drive change or a
        # branch switch follows) releases the new phase's functions with its own motion, as the
        # global loop does (there a function cannot clear round-off in so short a rest).
        # Released here, a relative velocity still on its zero reversed the part again and again
        # at one instant.
        nf = 0
    return xs, ph, nf


@njit(cache=True, inline="always")
def _march_release(rows, fn, nf, ph, rem, nk, bnd, k, basis, der):
    """Release the group's functions at the sub-piece's start (:func:`_release`; a slip that just
    started, its relative velocity leaving its zero with a clear slope, is left to the node table
    with ``skip = -1``). Returns the first function at or across its zero (-1: none) and whether a
    function is released for the whole rest of the piece."""
    _f_kind, _f_group, f_row, f_sgn, f_c0, f_c1, f_c2, f_skip, f_zero, _f_eval = fn
    cc, ss, sn, cs, bc, bs = basis
    whole = False
    for i in range(nf):
        if _clearly_free(rows, f_row[i], f_sgn[i], f_c0[i], f_c1[i], cc, ss, sn, cs, bc, bs):
            code, f_skip[i] = REL_FREE, 0.0
        elif (
            i == 0
            and ph != STICK
            and nk > 1
            and abs(f_sgn[0] * _row(rows, 1, cc, ss, sn, cs) + f_c0[0])
            <= 64.0 * EPS * (bnd[k, 1] + abs(f_c0[0]))
            and f_sgn[0] * _row(rows, 2, cc, ss, sn, cs) + f_c1[0]
            > DERIVATIVE_ZERO * (bnd[k, 2] + abs(f_c1[0]))
        ):
            # a slip just started: the relative velocity leaves its zero with a clear slope,
            # which the node table handles; the certified offset is worked out only if the
            # certified search has to start here (f_skip < 0)
            code, f_skip[i] = REL_SKIP, -1.0
        else:
            code, f_skip[i] = _release(
                rows, f_row[i], f_sgn[i], f_c0[i], f_c1[i], f_c2[i], rem, cc, ss, sn, cs, bc, bs,
                der,
            )  # fmt: skip
        f_zero[i] = code == REL_NEVER
        if code == REL_NOW:
            return i, whole
        if code == REL_SKIP and f_skip[i] >= rem:
            whole = True
    return -1, whole


@njit(cache=True, inline="always")
def _search_table(pieces, k, nodes, fn, nf, ph, rem, rows, piece, t0, bnd, basis, split_stack):
    """The node table's search on the rest ``rem`` of piece ``k`` (:mod:`.node_table`), a root it
    finds solved on the closed form. Returns whether the root's iteration converged, whether the
    certified search must still run (a cell stayed undecided, or a forward-slipping part may reach
    the track end) and with fresh basis values, from where, the function hit (-1: none) and the
    basis (at the root when one was found)."""
    _tab, _run_end, _base, _nk, _hk, ts, _T = nodes
    f_c0, f_c1, f_c2 = fn.c0, fn.c1, fn.c2
    consts = _table_tolerances(fn, ph, bnd, k, rem)
    fr, _nfast, _Bf, B3f, tol, _dtol, _errd = consts
    found, unsure, cell, basis = _table_search(
        nodes, fn, nf, ph, consts, rows, piece, basis, split_stack
    )
    if unsure:
        return True, True, True, cell[0], -1, basis
    s = 0.0
    hit = -1
    if found >= 0:
        line = (fn.sgn[found], f_c0[found], f_c1[found])
        solved, s, basis = _cell_root(line, cell, tol, B3f, rows, fr, t0, ts, piece, bnd, k, basis)
        if not solved:
            return False, False, False, s, -1, basis
        hit = found
    if ph == SLIP_FORWARD:
        # the track-end function falls while the part slips forward: positive at the end of the
        # sub-piece means positive all along
        cc, ss, sn, cs, _bc, _bs = basis
        s_end = s if hit >= 0 else rem
        x_end = _row(rows, 0, cc, ss, sn, cs) if hit >= 0 else pieces[k, P_XE]
        fe = f_c0[1] + x_end + s_end * (f_c1[1] + s_end * f_c2[1])
        scale = bnd[k, 0] + abs(f_c0[1]) + rem * (abs(f_c1[1]) + rem * abs(f_c2[1]))
        if fe <= 64.0 * EPS * scale:
            return True, True, True, 0.0, -1, basis
    return True, False, False, s, hit, basis


@njit(cache=True, inline="always")
def _march_certified(rows, fn, nf, ph, held, times, s, fresh, piece, basis, br, der, bounds_ready):
    """Certified safe steps (:mod:`.search`) for the group's functions from ``s`` to the first
    root on the rest ``rem`` of the piece (``times = (t0, ts, rem)``; ``fresh``: the basis is to
    be taken at ``s`` first), after releasing a slip's relative velocity that the table left
    (``skip < 0``). Returns the function hit (-1: none), where, the basis there, and that the
    piece's row bound terms are set up."""
    _f_kind, _f_group, f_row, f_sgn, f_c0, f_c1, f_c2, f_skip, f_zero, _f_eval = fn
    vals, bnds, _hbnds, r_abs_a, r_abs_b, r_amp, r_R = br
    sigma, lam, root, r1, w, phi = piece
    t0, ts, rem = times
    cc, ss, sn, cs, bc, bs = basis
    if s == 0.0 and f_skip[0] < 0.0:
        if fresh:
            cc, ss, sn, cs, bc, bs = _basis_all(ts, sigma, lam, root, r1, w, phi)
            fresh = False
        code, f_skip[0] = _release(
            rows, f_row[0], f_sgn[0], f_c0[0], f_c1[0], f_c2[0], rem, cc, ss, sn, cs, bc, bs, der
        )
        if code == REL_NOW:
            return 0, s, (cc, ss, sn, cs, bc, bs), bounds_ready
    if not bounds_ready:
        _bound_terms(rows, 0, 6, lam, root, r_abs_a, r_abs_b, r_amp, r_R)
    top = 4 if ph == STICK else 3  # highest row whose value/bound is needed, +1
    hit = -1
    while True:
        tau = ts + s
        if s > 0.0 or fresh:
            cc, ss, sn, cs, bc, bs = _basis_all(tau, sigma, lam, root, r1, w, phi)
            fresh = False
        if held:
            for r in range(6):
                vals[r] = 0.0
                bnds[r] = 0.0
            vals[0] = rows[0, 4]
            bnds[0] = abs(rows[0, 4])
        else:
            for r in range(top + 2):
                if r < top + 1:
                    vals[r] = _row(rows, r, cc, ss, sn, cs)
                _, bt = _bound_of_row(rows, r, bc, bs, r_abs_a, r_abs_b, r_amp, r_R)
                bnds[r] = bt
        t_res = 8.0 * EPS * (abs(t0) + tau + 1e-3)
        h = rem - s
        for i in range(nf):
            if f_zero[i]:
                continue
            if s < f_skip[i]:
                if f_skip[i] - s < h:
                    h = f_skip[i] - s
                continue
            r = f_row[i]
            sg = f_sgn[i]
            f = sg * vals[r] + f_c0[i] + s * (f_c1[i] + s * f_c2[i])
            h1, _ = _certified_step(f, s, sg, f_c0[i], f_c1[i], f_c2[i], r, vals, bnds, h)
            if h1 < 0.0 or h1 <= t_res:
                hit = i
                break
            if h1 < h:
                h = h1
        if hit >= 0 or h >= rem - s:
            break
        s += h
    return hit, s, (cc, ss, sn, cs, bc, bs), True


@njit(cache=True, inline="always")
def _march_samples(outputs, ns, start, t_stop, to_end, t_end, ph, g, gr, mb):
    """The group's members at the samples in ``[t0 + ts, t_stop)`` (``start = (t0, ts, xs)``,
    the carrier at ``xs`` there; ``to_end``: the run's last stretch, which includes ``t_end``),
    on the carrier's samples. Returns the next sample."""
    samples, _ns0, out_cx, out_cv, out_px, out_pv, out_pp = outputs
    _g_L, g_D, _g_mass, g_u, g_y, _g_slip, _g_lead, _g_phase, g_head = gr
    _m_group, m_next, m_o, _m_mass, _m_slip0, _m_exit_t = mb
    t0, ts, xs = start
    n_samples = samples.shape[0]
    ap = 0.0
    if ph == SLIP_BACKWARD:
        ap = g_D[g]
    elif ph == SLIP_FORWARD:
        ap = -g_D[g]
    while ns < n_samples and (samples[ns] < t_stop or (to_end and samples[ns] <= t_end)):
        xk = out_cx[ns]
        if ph == STICK:
            uk = out_cv[ns]
            yk = g_y[g]
        else:
            sk = samples[ns] - t0 - ts
            uk = g_u[g] + ap * sk
            yk = g_y[g] + sk * (g_u[g] + 0.5 * ap * sk) - (xk - xs)
        i = g_head[g]
        while i >= 0:
            out_px[ns, i] = m_o[i] + yk + xk
            out_pv[ns, i] = uk
            out_pp[ns, i] = ph
            i = m_next[i]
        ns += 1
    return ns


@njit(cache=True, inline="always")
def _end_state(rows, held, at_event, basis, pieces, k):
    """The carrier's ``x, v, a`` at the end of the sub-piece: from the basis at the event that
    ends it (``at_event``), else piece ``k``'s recorded end state."""
    if at_event:
        cc, ss, sn, cs, _bc, _bs = basis
        xe = _row(rows, 0, cc, ss, sn, cs)
        ve = 0.0 if held else _row(rows, 1, cc, ss, sn, cs)
        ae = 0.0 if held else _row(rows, 2, cc, ss, sn, cs)
        return xe, ve, ae
    return pieces[k, P_XE], pieces[k, P_VE], pieces[k, P_AE]


@njit(cache=True, inline="always")
def _march_event(g, kind, te, carrier, L, ns, gr, mb, outputs, events):
    """Group ``g``'s event of ``kind`` at ``te`` (the carrier at ``(x, v, a)`` there), logged to
    its row of ``events``: at a stick limit it starts slipping, where its relative velocity
    vanishes it sticks or reverses, at the track end its lead part leaves (its samples from
    ``ns`` on are NaN and EXITED)."""
    _g_L, _g_D, g_mass, g_u, g_y, g_slip, g_lead, g_phase, g_head = gr
    m_group, m_next, m_o, m_mass, m_slip0, m_exit_t = mb
    samples, _ns0, _out_cx, _out_cv, out_px, out_pv, out_pp = outputs
    ev_t, ev_kind, ev_part, ev_n = events
    xe, ve, ae = carrier
    n = ev_n[g]
    if kind in (F_STICK_UP, F_STICK_DOWN):
        g_phase[g] = _new_phase(kind, ae, L)
        g_u[g] = ve
        ev_kind[g, n] = EV_SLIP_START
        ev_part[g, n] = -1
    elif kind == F_RELVEL:
        g_u[g] = ve
        g_phase[g] = _new_phase(kind, ae, L)
        ev_kind[g, n] = EV_STICK if g_phase[g] == STICK else EV_REVERSAL
        ev_part[g, n] = -1
    else:
        lead_i = _exit_lead(
            g, te, xe, g_y, g_slip, g_mass, g_lead, g_head, m_group, m_next, m_o, m_mass,
            m_slip0, m_exit_t,
        )  # fmt: skip
        for j in range(ns, samples.shape[0]):
            out_px[j, lead_i] = np.nan
            out_pv[j, lead_i] = np.nan
            out_pp[j, lead_i] = EXITED
        ev_kind[g, n] = EV_EXIT
        ev_part[g, n] = lead_i
    ev_t[g, n] = te
    ev_n[g] = n + 1
