"""The group march, an accelerator for one-way coupling: the carrier's closed-form pieces are
recorded once by the global loop, then every group marches along them independently, in
parallel (:func:`advance_groups`).

Parts are handled in *groups*: parts with the same friction (``L = mu_s*g*kappa``, ``D =
mu_d*g*kappa``) that stick at the same time have identical velocity forever after, so a group
carries one velocity history; its members differ only by a track offset. With two-way coupling a
group also carries the summed mass of its members. :func:`advance` runs carrier and groups in one
event loop (any coupling); with one-way coupling :func:`advance` can instead record the carrier's
closed-form pieces, along which :func:`advance_groups` marches every group independently, in
parallel. There each piece is tabulated once for all groups (:func:`piece_tables`): a slipping
group passes whole runs of cells on which the carrier's jerk keeps its sign (its relative velocity
is concave or convex there) on a few table values, any group passes the other cells between nodes
on their end values (:func:`_cell`), solves a cell holding one root by a bracketed Halley
iteration on the closed form, halves undecided cells with exact evaluations, and falls back to the
safe steps above only when halving does not decide.

This file is over 800 lines because :func:`_march_group` is still one kernel of about 640 lines
(issue 30 cuts it next, as :mod:`.global_loop` was: into inlined steps over the records of
:mod:`.records`, compiled without numba's reference counting, checked bit for bit against the
golden outputs and timed against the old kernel in the same run).
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import numpy as np
from numba import njit, prange

from feeder_ros.physics.exact.closed_form import (
    SHIFT_CHAIN,
    _basis_all,
    _basis_bounds,
    _row,
    _row_bound,
    _shift_basis,
)
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
    NROWS,
    SLIP_BACKWARD,
    SLIP_FORWARD,
    STATUS_BUFFER_FULL,
    STATUS_DONE,
    STATUS_STUCK,
    STICK,
)
from feeder_ros.physics.exact.recorded_pieces import (
    BND_BC0,
    BND_BS0,
    BND_COS_PHI,
    BND_SHIFT,
    BND_SHIFT_MAX,
    BND_SIN_PHI,
    P_AE,
    P_LAM,
    P_LEN,
    P_MODE,
    P_PHI,
    P_R1,
    P_ROOT,
    P_ROWS,
    P_SIGMA,
    P_T0,
    P_VE,
    P_W,
    P_XE,
)
from feeder_ros.physics.exact.search import (
    CELL_ROOT,
    CELL_UNSURE,
    DERIVATIVE_ZERO,
    REL_FREE,
    REL_NEVER,
    REL_NOW,
    REL_SKIP,
    SPLIT_DEPTH,
    _bound_of_row,
    _bound_terms,
    _cell,
    _certified_step,
    _clearly_free,
    _release,
)


@njit(cache=True)
def _march_group(
    g,
    pieces,
    n_pieces,
    node_start,
    node_h,
    tab,
    bnd,
    run_end,
    track,
    t_end,
    samples,
    ns0,
    out_cx,
    out_cv,
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
    out_px,
    out_pv,
    out_pp,
    ev_t,
    ev_kind,
    ev_part,
    ev_n,
):
    """One group of parts along recorded carrier pieces (one-way coupling); returns a status.

    Group events go to row ``g`` of the event buffers with ``ev_part = -1`` (the caller expands
    them to the group's members), exits with the part index.
    """
    rows = np.zeros((NROWS, 5))
    der = np.zeros(5)
    n_samples = samples.shape[0]
    cap = ev_t.shape[1]
    L = g_L[g]
    D = g_D[g]
    ns = ns0
    zero_count = 0
    f_row = np.zeros(2, np.int64)
    f_kind = np.zeros(2, np.int64)
    f_sgn = np.zeros(2)
    f_c0 = np.zeros(2)
    f_c1 = np.zeros(2)
    f_c2 = np.zeros(2)
    f_skip = np.zeros(2)
    f_zero = np.zeros(2, np.bool_)
    r_abs_a = np.zeros(6)
    r_abs_b = np.zeros(6)
    r_amp = np.zeros(6)
    r_R = np.zeros(6)
    vals = np.zeros(6)
    bnds = np.zeros(6)
    sp_s = np.zeros(SPLIT_DEPTH)
    sp_v = np.zeros((SPLIT_DEPTH, 3))
    for k in range(n_pieces):
        t0 = pieces[k, P_T0]
        T = pieces[k, P_LEN]
        sigma = pieces[k, P_SIGMA]
        lam = pieces[k, P_LAM]
        root = pieces[k, P_ROOT]
        r1 = pieces[k, P_R1]
        w = pieces[k, P_W]
        phi = pieces[k, P_PHI]
        held = pieces[k, P_MODE] == 0.0
        for r in range(6):
            for j in range(5):
                rows[r, j] = pieces[k, P_ROWS + 5 * r + j]
        bounds_ready = False  # the certified search's per-row bound data (set up when needed)
        last = k == n_pieces - 1
        base = node_start[k]
        nk = node_start[k + 1] - base
        hk = node_h[k]
        ts = 0.0  # start of the current sub-piece (local time)
        at_ts = False  # the basis values are those at ts already (the last event's)
        while True:
            if g_head[g] < 0:
                # the group is empty: nothing more to do
                return STATUS_DONE
            if ev_n[g] + 2 > cap:
                return STATUS_BUFFER_FULL
            if ts == 0.0:
                cc, ss, sn, cs = 1.0, 0.0, bnd[k, BND_SIN_PHI], bnd[k, BND_COS_PHI]
                bc, bs = bnd[k, BND_BC0], bnd[k, BND_BS0]
            elif not at_ts:
                cc, ss, sn, cs, bc, bs = _basis_all(ts, sigma, lam, root, r1, w, phi)
            at_ts = False
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
                    0, g, track, xs, g_phase, g_D, g_u, g_y, g_lead, f_kind, f_row, f_sgn, f_c0,
                    f_c1, f_c2,
                )  # fmt: skip
                nf = 2
            rem = T - ts
            hit = -1
            if ph == STICK and nf == 2 and _row_bound(rows, 2, bc, bs) < L:
                nf = 0  # |a| stays below the stick limit for the rest of the piece
            if rem <= 4.0 * EPS * (abs(t0) + T):
                # an event within round-off of the end of the piece: the next piece (a drive
                # change or a branch switch follows) releases the new phase's functions with its
                # own motion, as the global loop does (there a function cannot clear round-off
                # in so short a rest). Released here, a relative velocity still on its zero
                # reversed the part again and again at one instant.
                nf = 0
            whole = False
            for i in range(nf):
                if _clearly_free(
                    rows, f_row[i], f_sgn[i], f_c0[i], f_c1[i], cc, ss, sn, cs, bc, bs
                ):
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
                    # a slip just started: the relative velocity leaves its zero with a clear
                    # slope, which the node table handles; the certified offset is worked out
                    # only if the certified search has to start here (f_skip < 0)
                    code, f_skip[i] = REL_SKIP, -1.0
                else:
                    code, f_skip[i] = _release(
                        rows,
                        f_row[i],
                        f_sgn[i],
                        f_c0[i],
                        f_c1[i],
                        f_c2[i],
                        rem,
                        cc,
                        ss,
                        sn,
                        cs,
                        bc,
                        bs,
                        der,
                    )
                f_zero[i] = code == REL_NEVER
                if code == REL_NOW:
                    hit = i
                    break
                if code == REL_SKIP and f_skip[i] >= rem:
                    whole = True
            s = 0.0
            certify = hit < 0 and nf > 0  # search with certified steps from s
            fresh = False  # the certified search starts with fresh basis values
            # (a function released for the whole rest of the piece, within round-off of zero
            # all along, goes to the certified search, which skips it as the global loop does)
            if certify and nk > 1 and rem > 0.0 and (ph != STICK or nf == 2) and not whole:
                # the node table first: cells without a root are passed on their end values, a
                # cell with one is solved by a bracketed Halley iteration; undecided cells (and
                # a part that may reach the track end) go to the certified search
                fr = f_row[0]
                nfast = 2 if ph == STICK else 1
                sgn0 = f_sgn[0]
                Bf = abs(sgn0) * bnd[k, fr + 2]
                B3f = abs(sgn0) * bnd[k, fr + 3]
                tol = 64.0 * EPS * (abs(sgn0) * bnd[k, fr] + abs(f_c0[0]) + rem * abs(f_c1[0]))
                dtol = DERIVATIVE_ZERO * (abs(sgn0) * bnd[k, fr + 1] + abs(f_c1[0]))
                runs = nfast == 1 and fr == 1  # slipping: the relative velocity, searched by runs
                c00 = f_c0[0]
                c10 = f_c1[0]
                errd = 64.0 * EPS * (bnd[k, 2] + abs(c10))  # round-off of its slope at a node
                declined = -1  # runs of cells before this node are left to the cell tests
                u0 = _row(rows, fr, cc, ss, sn, cs)
                u1 = _row(rows, fr + 1, cc, ss, sn, cs)
                u2 = _row(rows, fr + 2, cc, ss, sn, cs)
                i = min(int(ts / hk) + 1, nk - 1)
                while i < nk - 1 and i * hk <= ts:
                    i += 1
                sa = 0.0
                found = -1
                unsure = False
                for j in range(nf):
                    unsure = unsure or f_zero[j]
                sp = 0  # pending right ends from splitting undecided cells (exact values)
                while not unsure:
                    if sp == 0 and i < nk - 1:
                        while True:
                            at_run = False
                            while runs and i < nk - 1:
                                # the slip phase's runs first: on a run of cells where the
                                # carrier's jerk keeps its sign (piece_tables), the relative
                                # velocity f = sg*x' + c0 + c1*s is concave or convex (f'' =
                                # sg*x'''), and a few values decide its roots on all of it
                                c = i - 1
                                e = min(run_end[base + c] - base, nk - 2)
                                if e < i or base + c < declined:
                                    break
                                fa = sgn0 * u0 + c00 + c10 * sa
                                if not fa > tol and not sgn0 * u1 + c10 > dtol:
                                    break  # on its zero at sa, not leaving it: the cell tests
                                convex = sgn0 * tab[base + c, 3] > 0.0
                                skip = convex and sgn0 * u1 + c10 > errd  # rising all along
                                m = e + 1  # convex: the first node with f' >= -errd, if any
                                if convex and not skip and sgn0 * tab[base + e, 2] + c10 >= -errd:
                                    lo_n = c
                                    m = e
                                    while m - lo_n > 1:
                                        mid = (lo_n + m) // 2
                                        if sgn0 * tab[base + mid, 2] + c10 >= -errd:
                                            m = mid
                                        else:
                                            lo_n = mid
                                if not skip:
                                    # f is concave, or falling up to node m - 1: above zero up
                                    # to the node before the first node at or below tol
                                    lim = m - 1
                                    n = lim + 1
                                    if (
                                        lim > c
                                        and sgn0 * tab[base + lim, 1] + c00 + c10 * (lim * hk - ts)
                                        <= tol
                                    ):
                                        lo_n = c
                                        n = lim
                                        while n - lo_n > 1:
                                            mid = (lo_n + n) // 2
                                            sm = mid * hk - ts
                                            if sgn0 * tab[base + mid, 1] + c00 + c10 * sm <= tol:
                                                n = mid
                                            else:
                                                lo_n = mid
                                    if n - 1 > c:
                                        sa = (n - 1) * hk - ts
                                        u0 = tab[base + n - 1, 1]
                                        u1 = tab[base + n - 1, 2]
                                        u2 = tab[base + n - 1, 3]
                                        i = n
                                    if n <= lim:
                                        break  # the cell ending at that node: the tests below
                                    if m > e:
                                        skip = True  # concave or falling, above tol at node e
                                    else:
                                        # convex, its minimum in the cell from sa to node m: the
                                        # tangents at both ends bound it from below (they meet
                                        # at the weighted mean below; slopes off by <= errd)
                                        sq = m * hk - ts
                                        hq = sq - sa
                                        fp = sgn0 * u0 + c00 + c10 * sa
                                        fq = sgn0 * tab[base + m, 1] + c00 + c10 * sq
                                        slope_a = -(sgn0 * u1 + c10)
                                        slope_b = sgn0 * tab[base + m, 2] + c10
                                        if fq > tol and slope_a > errd and slope_b > errd:
                                            drop = slope_a * slope_b * hq / (slope_a + slope_b)
                                            low = (slope_a * fq + slope_b * fp) / (
                                                slope_a + slope_b
                                            )
                                            low -= drop
                                            slack = 8.0 * EPS * (fp + fq + drop) + errd * hq
                                            skip = low - slack > tol
                                        if not skip:
                                            declined = base + e  # the cell tests decide the run
                                            break
                                # no root from sa to node e: on to the next run
                                sa = e * hk - ts
                                u0 = tab[base + e, 1]
                                u1 = tab[base + e, 2]
                                u2 = tab[base + e, 3]
                                i = e + 1
                            # then the cells that their end values clear (the common case, and
                            # _cell's first test, made on the same values): the slopes and
                            # curvatures are not needed for them. The piece's last cell (its end
                            # is the piece's, not a node) goes to the full test below.
                            q = i
                            sq = sa
                            uq = u0
                            while q < nk - 1:
                                if (
                                    runs
                                    and q > i
                                    and run_end[base + q - 1] >= 0
                                    and base + q - 1 >= declined
                                ):
                                    at_run = True  # a run starts with this cell
                                    break
                                sbq = q * hk - ts
                                wq = tab[base + q, fr]
                                hq = sbq - sq
                                clear = True
                                for j in range(nfast):
                                    fa = f_sgn[j] * uq + f_c0[j] + f_c1[j] * sq
                                    fb = f_sgn[j] * wq + f_c0[j] + f_c1[j] * sbq
                                    if not (
                                        fa > tol
                                        and fb > tol
                                        and min(fa, fb) - 0.125 * Bf * hq * hq > tol
                                    ):
                                        clear = False
                                        break
                                if not clear:
                                    break
                                uq = wq
                                sq = sbq
                                q += 1
                            if q > i:
                                i = q
                                sa = sq
                                u0 = tab[base + q - 1, fr]
                                u1 = tab[base + q - 1, fr + 1]
                                u2 = tab[base + q - 1, fr + 2]
                            if not at_run:
                                break
                    if sp > 0:
                        sb = sp_s[sp - 1]
                        w0 = sp_v[sp - 1, 0]
                        w1 = sp_v[sp - 1, 1]
                        w2 = sp_v[sp - 1, 2]
                    else:
                        sb = (T if i == nk - 1 else i * hk) - ts
                        w0 = tab[base + i, fr]
                        w1 = tab[base + i, fr + 1]
                        w2 = tab[base + i, fr + 2]
                    split = False
                    for j in range(nfast):
                        sg = f_sgn[j]
                        c0 = f_c0[j]
                        c1 = f_c1[j]
                        code = _cell(
                            sg * u0 + c0 + c1 * sa,
                            sg * w0 + c0 + c1 * sb,
                            sg * u1 + c1,
                            sg * w1 + c1,
                            sg * u2,
                            sg * w2,
                            Bf,
                            B3f,
                            sb - sa,
                            tol,
                            dtol,
                        )
                        if code == CELL_UNSURE or (code == CELL_ROOT and found >= 0):
                            split = True
                        elif code == CELL_ROOT:
                            found = j
                    if split:
                        # halve the cell with an exact evaluation at its middle
                        found = -1
                        sm = 0.5 * (sa + sb)
                        if sp == SPLIT_DEPTH or not sa < sm < sb:
                            # (a cell one ulp wide cannot be halved: halving it again and again
                            # at the same depth never ends)
                            unsure = True
                            break
                        cc, ss, sn, cs, bc, bs = _basis_all(ts + sm, sigma, lam, root, r1, w, phi)
                        sp_s[sp] = sm
                        sp_v[sp, 0] = _row(rows, fr, cc, ss, sn, cs)
                        sp_v[sp, 1] = _row(rows, fr + 1, cc, ss, sn, cs)
                        sp_v[sp, 2] = _row(rows, fr + 2, cc, ss, sn, cs)
                        sp += 1
                        continue
                    if found >= 0 or (sp == 0 and i == nk - 1):
                        break
                    u0, u1, u2 = w0, w1, w2
                    sa = sb
                    if sp > 0:
                        sp -= 1
                    else:
                        i += 1
                if unsure:
                    s = sa
                    fresh = True
                else:
                    certify = False
                    if found >= 0:
                        sg = f_sgn[found]
                        c0 = f_c0[found]
                        c1 = f_c1[found]
                        fa = sg * u0 + c0 + c1 * sa
                        fb = sg * w0 + c0 + c1 * sb
                        da = sg * u1 + c1
                        db = sg * w1 + c1
                        hc = sb - sa
                        # start: one Newton step on the cubic Hermite interpolant from the
                        # secant's root (from the far end for a function released at a); more
                        # steps cost more than the Halley iterations they save
                        x = 1.0 if fa <= tol else fa / (fa - fb)
                        x2 = x * x
                        p = fa * (2.0 * x2 * x - 3.0 * x2 + 1.0) + fb * (3.0 * x2 - 2.0 * x2 * x)
                        p += hc * (da * (x2 * x - 2.0 * x2 + x) + db * (x2 * x - x2))
                        dp = (fa - fb) * (6.0 * x2 - 6.0 * x)
                        dp += hc * (da * (3.0 * x2 - 4.0 * x + 1.0) + db * (3.0 * x2 - 2.0 * x))
                        if dp != 0.0:
                            x = min(max(x - p / dp, 0.0), 1.0)
                        lo = sa
                        hi = sb
                        x = sa + x * hc
                        if not lo < x < hi:
                            x = 0.5 * (lo + hi)
                        solved = False
                        # the second and later iterates are usually within SHIFT_RAD of the last:
                        # their basis is shifted from there
                        # (their bounds are not needed before the root: taken once, there)
                        shift_max = bnd[k, BND_SHIFT_MAX]
                        x_b = np.nan  # where the basis values were taken
                        chain = 0
                        landed = False  # x is the root (the last step's error bound)
                        for _it in range(100):
                            tau = ts + x
                            if abs(x - x_b) <= shift_max and chain < SHIFT_CHAIN:
                                cc, ss, sn, cs = _shift_basis(
                                    x - x_b, bnd[k, BND_SHIFT], bnd[k, BND_SHIFT + 1],
                                    bnd[k, BND_SHIFT + 2], bnd[k, BND_SHIFT + 3],
                                    bnd[k, BND_SHIFT + 4], bnd[k, BND_SHIFT + 5],
                                    bnd[k, BND_SHIFT + 6], sigma, lam, w, cc, ss, sn, cs,
                                )  # fmt: skip
                                chain += 1
                            else:
                                cc, ss, sn, cs, bc, bs = _basis_all(
                                    tau, sigma, lam, root, r1, w, phi
                                )
                                chain = 0
                            x_b = x
                            if landed:
                                solved = True
                                break
                            f = sg * _row(rows, fr, cc, ss, sn, cs) + c0 + c1 * x
                            d = sg * _row(rows, fr + 1, cc, ss, sn, cs) + c1
                            f2 = sg * _row(rows, fr + 2, cc, ss, sn, cs)
                            if f > 0.0:
                                lo = x
                            elif f < 0.0:
                                hi = x
                            else:
                                solved = True
                                break
                            xn = np.nan
                            halley = False
                            if d != 0.0:
                                dn = f / d
                                den = 1.0 - 0.5 * dn * f2 / d  # Halley's correction
                                halley = den > 0.5
                                xn = x - (dn / den if halley else dn)
                            t_res = 8.0 * EPS * (abs(t0) + tau + 1e-3)
                            dx = abs(xn - x)
                            if dx <= t_res:
                                solved = True  # converged (its step may leave the bracket)
                                break
                            if not lo < xn < hi:
                                xn = 0.5 * (lo + hi)
                            elif halley and dx <= shift_max:
                                # Halley's error goes as (c2^2 - c3)*e^3 (c_k = f^(k)/(k!*f')):
                                # bounded with |f'''| <= B3f, four times over, within t_res, the
                                # step lands on the root: only its basis is taken there
                                c2 = 0.5 * f2 / d
                                landed = (
                                    4.0 * (c2 * c2 + B3f / (6.0 * abs(d))) * dx * dx * dx <= t_res
                                )
                            if hi - lo <= t_res:
                                solved = True
                                break
                            x = xn
                        if not solved:
                            return STATUS_STUCK
                        if chain > 0:
                            bc, bs = _basis_bounds(tau, sigma, lam, root, r1)
                        s = x
                        hit = found
                    if ph == SLIP_FORWARD:
                        # the track-end function falls while the part slips forward: positive
                        # at the end of the sub-piece means positive all along
                        s_end = s if hit >= 0 else rem
                        x_end = _row(rows, 0, cc, ss, sn, cs) if hit >= 0 else pieces[k, P_XE]
                        fe = f_c0[1] + x_end + s_end * (f_c1[1] + s_end * f_c2[1])
                        scale = bnd[k, 0] + abs(f_c0[1]) + rem * (abs(f_c1[1]) + rem * abs(f_c2[1]))
                        if fe <= 64.0 * EPS * scale:
                            certify = True
                            fresh = True
                            s = 0.0
                            hit = -1
            if certify and s == 0.0 and f_skip[0] < 0.0:
                if fresh:
                    cc, ss, sn, cs, bc, bs = _basis_all(ts, sigma, lam, root, r1, w, phi)
                    fresh = False
                code, f_skip[0] = _release(
                    rows,
                    f_row[0],
                    f_sgn[0],
                    f_c0[0],
                    f_c1[0],
                    f_c2[0],
                    rem,
                    cc,
                    ss,
                    sn,
                    cs,
                    bc,
                    bs,
                    der,
                )
                if code == REL_NOW:
                    hit = 0
                    certify = False
            if certify and not bounds_ready:
                _bound_terms(rows, 0, 6, lam, root, r_abs_a, r_abs_b, r_amp, r_R)
                bounds_ready = True
            if certify:
                top = 4 if ph == STICK else 3  # highest row whose value/bound is needed, +1
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
                        h1, _ = _certified_step(
                            f, s, sg, f_c0[i], f_c1[i], f_c2[i], r, vals, bnds, h
                        )
                        if h1 < 0.0 or h1 <= t_res:
                            hit = i
                            break
                        if h1 < h:
                            h = h1
                    if hit >= 0 or h >= rem - s:
                        break
                    s += h
            tau_e = ts + s if hit >= 0 else T
            t_stop = t0 + tau_e
            # samples in [t0 + ts, t_stop) (the run's last piece includes t_end)
            ap = 0.0
            if ph == SLIP_BACKWARD:
                ap = D
            elif ph == SLIP_FORWARD:
                ap = -D
            while ns < n_samples and (
                samples[ns] < t_stop or (last and hit < 0 and samples[ns] <= t_end)
            ):
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
            # state at tau_e (the piece's recorded end state when it runs to its end)
            if hit >= 0:  # the basis values are those at tau_e already
                xe = _row(rows, 0, cc, ss, sn, cs)
                ve = 0.0 if held else _row(rows, 1, cc, ss, sn, cs)
                ae = 0.0 if held else _row(rows, 2, cc, ss, sn, cs)
            else:
                xe = pieces[k, P_XE]
                ve = pieces[k, P_VE]
                ae = pieces[k, P_AE]
            se = tau_e - ts
            _end_group(g, se, xs, xe, ve, g_phase, g_D, g_u, g_y, g_slip)
            if hit < 0:
                break
            at_ts = True
            zero_count, stuck = _count_repeat(zero_count, se == 0.0, f_kind[hit])
            if stuck:
                return STATUS_STUCK
            te = t0 + tau_e
            kind = f_kind[hit]
            n = ev_n[g]
            if kind in (F_STICK_UP, F_STICK_DOWN):
                g_phase[g] = _new_phase(kind, ae, L)
                g_u[g] = ve
                ev_t[g, n] = te
                ev_kind[g, n] = EV_SLIP_START
                ev_part[g, n] = -1
                ev_n[g] = n + 1
            elif kind == F_RELVEL:
                g_u[g] = ve
                g_phase[g] = _new_phase(kind, ae, L)
                ev_kind[g, n] = EV_STICK if g_phase[g] == STICK else EV_REVERSAL
                ev_t[g, n] = te
                ev_part[g, n] = -1
                ev_n[g] = n + 1
            else:
                lead_i = _exit_lead(
                    g, te, xe, g_y, g_slip, g_mass, g_lead, g_head, m_group, m_next, m_o, m_mass,
                    m_slip0, m_exit_t,
                )  # fmt: skip
                for j in range(ns, n_samples):
                    out_px[j, lead_i] = np.nan
                    out_pv[j, lead_i] = np.nan
                    out_pp[j, lead_i] = EXITED
                ev_t[g, n] = te
                ev_kind[g, n] = EV_EXIT
                ev_part[g, n] = lead_i
                ev_n[g] = n + 1
            ts = tau_e
    return STATUS_DONE


@njit(cache=True, parallel=True)
def advance_groups(
    pieces,
    n_pieces,
    node_start,
    node_h,
    tab,
    bnd,
    run_end,
    track,
    t_end,
    samples,
    ns0,
    out_cx,
    out_cv,
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
    out_px,
    out_pv,
    out_pp,
    ev_t,
    ev_kind,
    ev_part,
    ev_n,
    status,
):
    """All groups along recorded carrier pieces, in parallel (one-way coupling: independent).

    ``status[g]`` receives each group's status; a group stopped by a full event buffer (row ``g``)
    must be re-run with more room from a saved copy of its state.
    """
    for g in prange(g_L.shape[0]):
        if g_head[g] < 0 or status[g] == STATUS_DONE:
            continue
        status[g] = _march_group(
            g,
            pieces,
            n_pieces,
            node_start,
            node_h,
            tab,
            bnd,
            run_end,
            track,
            t_end,
            samples,
            ns0,
            out_cx,
            out_cv,
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
            out_px,
            out_pv,
            out_pp,
            ev_t,
            ev_kind,
            ev_part,
            ev_n,
        )
