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
    _basis_bounds,
    _fill_rows,
    _row,
    _row_bound,
    _shift_basis,
    _shift_coefficients,
    _shift_max,
    _sincos,
)
from feeder_ros.physics.exact.event_steps import (
    _classify,
    _count_repeat,
    _end_group,
    _exit_lead,
    _log,
    _log_group,
    _new_phase,
    _slip_functions,
    _stick_functions,
)
from feeder_ros.physics.exact.layout import (
    COUPLING,
    DAMPING,
    EPS,
    EV_BRANCH,
    EV_DRIVE,
    EV_EXIT,
    EV_REVERSAL,
    EV_SLIDE_END,
    EV_SLIDE_START,
    EV_SLIP_START,
    EV_STICK,
    F_BRANCH,
    F_EXIT,
    F_RELVEL,
    F_SLIDE_BWD,
    F_SLIDE_FWD,
    F_STICK_DOWN,
    F_STICK_UP,
    K_BWD,
    K_FWD,
    LOG_EVENTS,
    M_BASE,
    M_ONEWAY,
    N_ROT,
    NROWS,
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
from feeder_ros.physics.exact.sampling import _part_samples, _shifted_samples
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
)


@njit(cache=True)
def advance(
    model,
    d_start,
    d_omega,
    d_amp,
    d_phase,
    d_logged,
    state,
    g_L,
    g_D,
    g_mass,
    g_u,
    g_y,
    g_slip,
    g_lead,
    g_phase,
    g_head,
    m_group,
    m_next,
    m_o,
    m_mass,
    m_slip0,
    m_exit_t,
    t_end,
    samples,
    out_cx,
    out_cv,
    out_ca,
    out_cb,
    out_px,
    out_pv,
    out_pp,
    ev_t,
    ev_kind,
    ev_part,
    counters,
    pieces,
):
    """Advance the carrier and all part groups from ``state[S_T]`` to ``t_end`` (in place).

    ``counters`` = [samples written, events written, status, safe steps taken (diagnostic),
    pieces recorded]. If ``pieces`` has rows, every closed-form piece of the carrier is recorded
    there (see :func:`_record_piece`) for :func:`advance_groups`.
    Samples ``samples[counters[0]:]`` with
    time < the end of the run (<= ``t_end`` for the last piece) are written. Returns the status:
    0 done, 1 event buffer full (state saved at the event time; call again with room), 2 exact
    resonance of an undamped branch, 3 stuck (an event repeated at one instant without progress).
    """
    n_groups = g_L.shape[0]
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

    rows = np.zeros((NROWS, 5))
    nfmax = 4 + 2 * n_groups
    f_kind = np.zeros(nfmax, np.int64)
    f_group = np.zeros(nfmax, np.int64)
    f_row = np.zeros(nfmax, np.int64)
    f_sgn = np.zeros(nfmax)
    f_c0 = np.zeros(nfmax)
    f_c1 = np.zeros(nfmax)
    f_c2 = np.zeros(nfmax)
    f_skip = np.zeros(nfmax)
    f_zero = np.zeros(nfmax, np.bool_)
    f_eval = np.zeros(nfmax, np.bool_)
    vals = np.zeros(NROWS)
    r_abs_a = np.zeros(NROWS)
    r_abs_b = np.zeros(NROWS)
    r_amp = np.zeros(NROWS)
    r_R = np.zeros(NROWS)
    der = np.zeros(5)
    bnds = np.zeros(NROWS)
    hbnds = np.zeros(NROWS)
    zero_count = 0
    # output samples: the basis is shifted by the nominal spacing h_nom between samples
    h_nom = 0.0
    if n_samples >= 2:
        h_nom = (samples[n_samples - 1] - samples[0]) / (n_samples - 1)
    rot_key = np.full((2, 3), np.nan)
    rot = np.zeros((2, 4, N_ROT))  # per branch: C, S, sin, cos of the shifts j*h_nom
    rot_n = np.ones(2, np.int64)

    record = pieces.shape[0] > 0
    # a part event with one-way coupling leaves the carrier's closed form as it is: the loop then
    # continues the same piece from the event's local time ts (cont) instead of restarting it
    cont = False
    ts = 0.0
    xs = 0.0
    vs = 0.0
    tb = 0.0
    jb = N_ROT
    cb = 1.0
    sb = 0.0
    snb = 0.0
    csb = 1.0
    n_cf = 0
    t0 = 0.0
    x0 = 0.0
    v0 = 0.0
    mode = 1.0
    seg = 0
    w = 0.0
    A = 0.0
    phi = 0.0
    piece_end = 0.0
    drive_end = False
    T = 0.0
    m = 1.0
    F0 = 0.0
    held = False
    k = 0.0
    sigma = 0.0
    lam = 0.0
    root = 0.0
    r1 = 0.0
    a2 = a3 = a4 = a5 = b3 = b4 = b5 = 0.0  # the piece's shift coefficients (_shift_basis)
    shift_max = 0.0
    e_cc = e_ss = e_sn = e_cs = e_bc = e_bs = 0.0  # the basis (and bounds) at the last event
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
            x0 = state[S_X]
            v0 = state[S_V]
            mode = state[S_MODE]
            seg = int(state[S_SEG])
            nseg = d_start.shape[0]
            while seg + 1 < nseg and d_start[seg + 1] <= t0:
                # the last piece ended on an event within round-off of a drive change (its end
                # time rounded onto the change): the change is logged here
                seg += 1
                if log_events and d_logged[seg] != 0:
                    _log(ev_t, ev_kind, ev_part, counters, d_start[seg], EV_DRIVE, -1)
            state[S_SEG] = seg
            w = d_omega[seg]
            A = d_amp[seg]
            phi = np.fmod(d_phase[seg] + w * (t0 - d_start[seg]), 2.0 * math.pi)
            piece_end = t_end
            drive_end = False
            if seg + 1 < nseg and d_start[seg + 1] < t_end:
                piece_end = d_start[seg + 1]
                drive_end = True
            T = piece_end - t0

            # carrier mass and parts' reaction force
            if two_way:
                m = model[M_BASE]
                F0 = 0.0
                for g in range(n_groups):
                    if g_head[g] < 0:
                        continue
                    if g_phase[g] == STICK:
                        m += g_mass[g]
                    elif g_phase[g] == SLIP_BACKWARD:
                        F0 -= g_mass[g] * g_D[g]
                    else:
                        F0 += g_mass[g] * g_D[g]
            else:
                m = model[M_ONEWAY]
                F0 = 0.0
            held = mode == 0.0
            k = kf if mode >= 0.0 else kb
            sigma = -c / (2.0 * m)
            lam = sigma * sigma - k / m
            root = math.sqrt(abs(lam))
            r1 = 0.0
            if lam > 0.0:
                r1 = (k / m) / (sigma - root)
            a2, a3, a4, a5, b3, b4, b5 = _shift_coefficients(sigma, lam)
            shift_max = _shift_max(sigma, root, w)
            if not _fill_rows(rows, sigma, lam, A, w, phi, m, c, k, F0, x0, v0, held):
                counters[2] = STATUS_RESONANCE
                return STATUS_RESONANCE
            xs = x0
            vs = v0

        # ---- event functions of this piece
        # (the carrier's functions keep their state when the piece continues after a part event)
        nf = n_cf
        if not cont:
            nf = 0
            if not held:
                f_kind[nf] = F_BRANCH
                f_row[nf] = switch
                f_sgn[nf] = mode
                f_c0[nf] = 0.0
                f_c1[nf] = 0.0
                f_c2[nf] = 0.0
                nf += 1
            else:
                f_kind[nf] = F_SLIDE_FWD
                f_row[nf] = 6
                f_sgn[nf] = -1.0
                f_c0[nf] = -(F0 - kf * x0)
                f_c1[nf] = 0.0
                f_c2[nf] = 0.0
                nf += 1
                f_kind[nf] = F_SLIDE_BWD
                f_row[nf] = 6
                f_sgn[nf] = 1.0
                f_c0[nf] = F0 - kb * x0
                f_c1[nf] = 0.0
                f_c2[nf] = 0.0
                nf += 1
            n_cf = nf
        lmin = np.inf
        for g in range(n_groups):
            if g_head[g] < 0:
                continue
            if g_phase[g] == STICK:
                g_u[g] = vs
                if g_L[g] < lmin:
                    lmin = g_L[g]
                if g_lead[g] + g_y[g] >= track:
                    f_kind[nf] = F_EXIT
                    f_group[nf] = g
                    f_row[nf] = 0
                    f_sgn[nf] = 0.0
                    f_c0[nf] = track - g_lead[g] - g_y[g]
                    f_c1[nf] = 0.0
                    f_c2[nf] = 0.0
                    nf += 1
            else:
                _slip_functions(
                    nf, g, track, xs, g_phase, g_D, g_u, g_y, g_lead, f_kind, f_row, f_sgn, f_c0,
                    f_c1, f_c2,
                )  # fmt: skip
                f_group[nf] = g
                f_group[nf + 1] = g
                nf += 2
        if lmin < np.inf:
            _stick_functions(nf, lmin, f_kind, f_row, f_sgn, f_c0, f_c1, f_c2)
            nf += 2

        # ---- release functions that start on (or across) their zero (at ts; the part's
        # polynomials are in s = tau - ts)
        chain = 0
        if ts == 0.0:
            cc = 1.0
            ss = 0.0
            sn, cs = _sincos(phi)
            bc, bs = _basis_bounds(0.0, sigma, lam, root, r1)
        elif cont:
            # after a part event: the basis at the event (the stop that found it)
            cc, ss, sn, cs, bc, bs = e_cc, e_ss, e_sn, e_cs, e_bc, e_bs
            chain = e_chain
        else:
            cc, ss, sn, cs, bc, bs = _basis_all(ts, sigma, lam, root, r1, w, phi)
        stick_bound = _row_bound(rows, 2, bc, bs)
        tau_e = T
        hit = -1
        for i in range(nf):
            f_eval[i] = False
        for i in range(n_cf if cont else 0, nf):
            if _clearly_free(rows, f_row[i], f_sgn[i], f_c0[i], f_c1[i], cc, ss, sn, cs, bc, bs):
                code, s_rel = REL_FREE, 0.0
            else:
                code, s_rel = _release(
                    rows,
                    f_row[i],
                    f_sgn[i],
                    f_c0[i],
                    f_c1[i],
                    f_c2[i],
                    T - ts,
                    cc,
                    ss,
                    sn,
                    cs,
                    bc,
                    bs,
                    der,
                )
            f_skip[i] = ts + s_rel
            f_zero[i] = code == REL_NEVER
            if code == REL_NOW:
                tau_e = ts
                hit = i
                break
            if (f_kind[i] == F_STICK_UP or f_kind[i] == F_STICK_DOWN) and stick_bound < lmin:
                f_zero[i] = True  # |a| stays below every stick limit for the whole piece

        # ---- safe stepping to the first root
        # per-row bound pieces: |alpha|, |beta|, amplitude form (under-damped), sinusoid, constant
        lo = 6 if held else 0
        hi_r = 10 if held else 0
        if not held:
            # only the rows the piece's functions need: value up to r + 2, bound up to r + 3
            for i in range(nf):
                if not f_zero[i] and f_row[i] + 4 > hi_r:
                    hi_r = f_row[i] + 4
        _bound_terms(rows, lo, hi_r, lam, root, r_abs_a, r_abs_b, r_amp, r_R)
        tau = ts
        e_cc, e_ss, e_sn, e_cs, e_bc, e_bs = cc, ss, sn, cs, bc, bs
        e_chain = chain
        if hit < 0:
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
                        hb, bt = _bound_of_row(rows, r, bc, bs, r_abs_a, r_abs_b, r_amp, r_R)
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
                        hit = i
                        break
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
                        hit = i
                        break
                    f_skip[i] = tau + h1
                    f_eval[i] = True
                    if f_skip[i] < t_next:
                        t_next = f_skip[i]
                if hit >= 0:
                    tau_e = tau
                    e_cc, e_ss, e_sn, e_cs, e_bc, e_bs = cc, ss, sn, cs, bc, bs
                    e_chain = chain
                    break
                if t_next >= T:
                    tau_e = T
                    break
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

        # ---- samples in [t0, t0 + tau_e)  (the last piece of the run includes t_end)
        last = hit < 0 and not drive_end
        t_stop = t0 + tau_e
        ns = counters[0]
        can_rot = h_nom > 0.0 and ns + 1 < n_samples and samples[ns + 1] <= t_stop
        slot = 0 if mode >= 0.0 else 1
        if can_rot and (
            rot_key[slot, 0] != sigma or rot_key[slot, 1] != lam or rot_key[slot, 2] != w
        ):
            # the shifts by j*h_nom of this basis, filled on demand (cached per branch: the
            # pieces alternate between two parameter sets)
            rot_key[slot, 0] = sigma
            rot_key[slot, 1] = lam
            rot_key[slot, 2] = w
            rot_n[slot] = 1
        # the first-order correction below is exact to round-off for |dt|*omega <= 1e-8
        eps_rec = 1e-8 / (abs(sigma) + root + w + 1e-300)
        if not cont:
            # a new closed form: the next sample is evaluated directly (a continued piece keeps
            # its last directly evaluated sample as the base of the shifts)
            tb = 0.0
            jb = N_ROT
        while ns < n_samples and (samples[ns] < t_stop or (last and samples[ns] <= t_end)):
            # a block of samples shifted from the last directly evaluated one (exact shift
            # identities C(t+h) = C(h)C + lam*S(h)S, S(t+h) = S(h)C + C(h)S, the drive's angle
            # addition, and a first-order Taylor term for the round-off difference dt between a
            # sample and tb + j*h_nom), or else one sample evaluated directly
            nb = 0
            if can_rot and jb + 1 < N_ROT:
                cap_b = N_ROT - 1 - jb
                while nb < cap_b and ns + nb < n_samples:
                    tq = samples[ns + nb]
                    if not (tq < t_stop or (last and tq <= t_end)):
                        break
                    if not abs((tq - t0) - (tb + (jb + 1 + nb) * h_nom)) <= eps_rec:
                        break
                    nb += 1
                if jb + nb >= rot_n[slot]:
                    # the shifts by j*h_nom of this basis, filled on demand
                    for jr in range(rot_n[slot], jb + nb + 1):
                        rc, rs, rsw, rcw = _basis(jr * h_nom, sigma, lam, root, r1, w, 0.0)
                        rot[slot, 0, jr] = rc
                        rot[slot, 1, jr] = rs
                        rot[slot, 2, jr] = rsw
                        rot[slot, 3, jr] = rcw
                    rot_n[slot] = jb + nb + 1
            if nb > 0:
                _shifted_samples(
                    samples, ns, nb, jb, t0, tb, h_nom, rot[slot], cb, sb, snb, csb, sigma, lam,
                    w, rows, held, mode, out_cx, out_cv, out_ca, out_cb,
                )  # fmt: skip
                if n_members > 0:
                    _part_samples(
                        samples, ns, nb, t0, ts, xs, out_cx, out_cv, g_phase, g_u, g_y, g_D,
                        m_group, m_o, out_px, out_pv, out_pp,
                    )  # fmt: skip
                jb += nb
                ns += nb
                continue
            tk = samples[ns] - t0
            cb, sb, snb, csb = _basis(tk, sigma, lam, root, r1, w, phi)
            tb = tk
            jb = 0
            xk = _row(rows, 0, cb, sb, snb, csb)
            out_cx[ns] = xk
            out_cv[ns] = 0.0 if held else _row(rows, 1, cb, sb, snb, csb)
            out_ca[ns] = 0.0 if held else _row(rows, 2, cb, sb, snb, csb)
            out_cb[ns] = int(mode)
            if n_members > 0:
                _part_samples(
                    samples, ns, 1, t0, ts, xs, out_cx, out_cv, g_phase, g_u, g_y, g_D, m_group,
                    m_o, out_px, out_pv, out_pp,
                )  # fmt: skip
            ns += 1
        counters[0] = ns

        # ---- state at the end of the piece
        if hit >= 0:
            cc, ss, sn, cs = e_cc, e_ss, e_sn, e_cs
        else:
            cc, ss, sn, cs = _basis(tau_e, sigma, lam, root, r1, w, phi)
        xe = _row(rows, 0, cc, ss, sn, cs)
        ve = 0.0 if held else _row(rows, 1, cc, ss, sn, cs)
        ae = 0.0 if held else _row(rows, 2, cc, ss, sn, cs)
        Fe = A * sn
        dFe = A * w * cs
        te = t0 + tau_e
        for g in range(n_groups):
            if g_head[g] >= 0:
                _end_group(g, tau_e - ts, xs, xe, ve, g_phase, g_D, g_u, g_y, g_slip)
        if record and tau_e > 0.0:
            _record_piece(
                pieces, counters[4], t0, tau_e, sigma, lam, root, r1, w, phi, mode, rows, xe, ve, ae
            )
            counters[4] += 1
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
        zero_count, stuck = _count_repeat(zero_count, tau_e == ts, f_kind[hit])
        if stuck:
            counters[2] = STATUS_STUCK
            return STATUS_STUCK
        kind = f_kind[hit]
        if kind == F_BRANCH:
            if switch == 0:
                state[S_X] = 0.0
                new_mode = -mode
                if ve == 0.0:
                    new_mode = _classify(0, mode, 0.0, 0.0, Fe, dFe, F0, m, kf, kb)
            else:
                state[S_V] = 0.0
                new_mode = _classify(1, mode, xe, 0.0, Fe, dFe, F0, m, kf, kb)
            if new_mode != mode and log_events:
                ev = EV_SLIDE_START if new_mode == 0.0 else EV_BRANCH
                _log(ev_t, ev_kind, ev_part, counters, te, ev, -1)
            state[S_MODE] = new_mode
        elif kind in (F_SLIDE_FWD, F_SLIDE_BWD):
            state[S_V] = 0.0
            state[S_MODE] = 1.0 if kind == F_SLIDE_FWD else -1.0
            if log_events:
                _log(ev_t, ev_kind, ev_part, counters, te, EV_SLIDE_END, -1)
        elif kind in (F_STICK_UP, F_STICK_DOWN):
            new_phase = _new_phase(kind, 0.0, 0.0)
            limit = max(abs(ae), lmin) * (1.0 + 1e-12)
            for g in range(n_groups):
                if g_head[g] >= 0 and g_phase[g] == STICK and g_L[g] <= limit:
                    g_phase[g] = new_phase
                    g_u[g] = ve
                    if log_events:
                        _log_group(
                            ev_t, ev_kind, ev_part, counters, te, EV_SLIP_START, g, g_head, m_next
                        )
        elif kind == F_RELVEL:
            g = f_group[hit]
            g_u[g] = ve
            a_test = ae
            if two_way and not held:
                # carrier acceleration with this group stuck to it
                Fs = F0 + (
                    g_mass[g] * g_D[g] if g_phase[g] == SLIP_BACKWARD else -g_mass[g] * g_D[g]
                )
                a_test = (Fe + Fs - c * ve - k * xe) / (m + g_mass[g])
            g_phase[g] = _new_phase(kind, a_test, g_L[g])
            if g_phase[g] == STICK:
                if log_events:
                    _log_group(ev_t, ev_kind, ev_part, counters, te, EV_STICK, g, g_head, m_next)
                # merge with a sticking group of the same friction: identical futures
                for h2 in range(n_groups):
                    if (
                        h2 != g
                        and g_head[h2] >= 0
                        and g_phase[h2] == STICK
                        and g_L[h2] == g_L[g]
                        and g_D[h2] == g_D[g]
                    ):
                        shift = g_y[g] - g_y[h2]
                        i = g_head[g]
                        tail = -1
                        while i >= 0:
                            m_o[i] += shift
                            m_group[i] = h2
                            m_slip0[i] = g_slip[h2] - (g_slip[g] - m_slip0[i])
                            tail = i
                            i = m_next[i]
                        m_next[tail] = g_head[h2]
                        g_head[h2] = g_head[g]
                        g_head[g] = -1
                        g_mass[h2] += g_mass[g]
                        g_lead[h2] = max(g_lead[h2], g_lead[g] + shift)
                        break
            elif log_events:
                _log_group(ev_t, ev_kind, ev_part, counters, te, EV_REVERSAL, g, g_head, m_next)
        elif kind == F_EXIT:
            lead_i = _exit_lead(
                f_group[hit], te, xe, g_y, g_slip, g_mass, g_lead, g_head, m_group, m_next, m_o,
                m_mass, m_slip0, m_exit_t,
            )  # fmt: skip
            if log_events:
                _log(ev_t, ev_kind, ev_part, counters, te, EV_EXIT, lead_i)
        if not two_way and not record and kind >= F_STICK_UP:
            # a part event: the carrier's piece goes on from here
            cont = True
            ts = tau_e
            xs = xe
            vs = ve
    counters[2] = STATUS_DONE
    return STATUS_DONE
