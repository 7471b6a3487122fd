"""The group march's fast root search on a recorded piece's node table (:func:`piece_tables`): the
accelerator that lets :mod:`.group_march` pass most of a piece without a certified step.

A group's first event function (the relative velocity of a slipping group, the stick limits of a
sticking one) is ``sg*x^(r)(tau) + c0 + c1*s`` along the carrier's tabulated values. Runs of
cells on which the carrier's jerk keeps its sign are passed on a few table values (a slipping
group's relative velocity is concave or convex there: :func:`_pass_runs`), other cells on their
end values when those clear them with room (:func:`_pass_clear_cells`); a cell holding one root
is solved by a bracketed Halley iteration on the closed form (:func:`_cell_root`), an undecided
cell is halved with exact evaluations. What the table cannot decide goes back to the certified
search (:func:`~feeder_ros.physics.exact.search._certified_step`) from where it stopped.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import numpy as np
from numba import njit

from feeder_ros.physics.exact.closed_form import (
    SHIFT_CHAIN,
    _basis_all,
    _basis_bounds,
    _row,
    _shift_basis,
)
from feeder_ros.physics.exact.layout import EPS, STICK
from feeder_ros.physics.exact.recorded_pieces import BND_SHIFT, BND_SHIFT_MAX
from feeder_ros.physics.exact.search import (
    CELL_ROOT,
    CELL_UNSURE,
    DERIVATIVE_ZERO,
    SPLIT_DEPTH,
    _cell,
)


@njit(cache=True, inline="always")
def _table_tolerances(fn, ph, bnd, k, rem):
    """The table search's constants for the first event function on piece ``k`` (``rem`` left):
    its row, the number of functions the cells test (both stick limits, or the relative
    velocity), the bounds of its second and third derivatives, the round-off of its value and
    slope, and that of a relative velocity's slope at a node."""
    f_row, f_sgn, f_c0, f_c1 = fn.row, fn.sgn, fn.c0, fn.c1
    fr = f_row[0]
    nfast = 2 if ph == STICK else 1
    sgn0 = f_sgn[0]
    Bf = abs(sgn0) * bnd[k, fr + 2]
    B3f = abs(sgn0) * bnd[k, fr + 3]
    tol = 64.0 * EPS * (abs(sgn0) * bnd[k, fr] + abs(f_c0[0]) + rem * abs(f_c1[0]))
    dtol = DERIVATIVE_ZERO * (abs(sgn0) * bnd[k, fr + 1] + abs(f_c1[0]))
    errd = 64.0 * EPS * (bnd[k, 2] + abs(f_c1[0]))  # round-off of a relative velocity's slope
    return fr, nfast, Bf, B3f, tol, dtol, errd


@njit(cache=True, inline="always")
def _pass_runs(nodes, line, at, declined):
    """Pass the runs of cells where the carrier's jerk keeps its sign (``run_end``) from the
    cursor ``at = (i, sa, u0, u1, u2)`` (the next node, the local time and the relative
    velocity's row values there) while they provably hold no root of ``line`` = the slipping
    group's relative velocity ``f = sg*x' + c00 + c10*s`` (``f'' = sg*x'''``, so concave or convex
    on a run) with its round-off ``tol, dtol, errd``. Returns the cursor where a cell must be
    tested, and the node before which runs are left to the cell tests (``declined``)."""
    tab, run_end, base, nk, hk, ts = nodes
    sgn0, c00, c10, tol, dtol, errd = line
    i, sa, u0, u1, u2 = at
    while i < nk - 1:
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
            # f is concave, or falling up to node m - 1: above zero up to the node before the
            # first node at or below tol
            lim = m - 1
            n = lim + 1
            if lim > c and sgn0 * tab[base + lim, 1] + c00 + c10 * (lim * hk - ts) <= tol:
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
                # convex, its minimum in the cell from sa to node m: the tangents at both ends
                # bound it from below (they meet at the weighted mean below; slopes off by
                # <= errd)
                sq = m * hk - ts
                hq = sq - sa
                fp = sgn0 * u0 + c00 + c10 * sa
                fq = sgn0 * tab[base + m, 1] + c00 + c10 * sq
                slope_a = -(sgn0 * u1 + c10)
                slope_b = sgn0 * tab[base + m, 2] + c10
                if fq > tol and slope_a > errd and slope_b > errd:
                    drop = slope_a * slope_b * hq / (slope_a + slope_b)
                    low = (slope_a * fq + slope_b * fp) / (slope_a + slope_b)
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
    return (i, sa, u0, u1, u2), declined


@njit(cache=True, inline="always")
def _pass_clear_cells(nodes, fn, nfast, fr, Bf, tol, runs, declined, at):
    """Pass the cells that the tested functions' end values clear with room for their curvature
    (``|f''| <= Bf``; the common case, and :func:`_cell`'s first test on the same values) from
    the cursor ``at``, up to the piece's last cell (its end is the piece's, not a node: the full
    test). Returns the cursor and True when a run of :func:`_pass_runs` starts there."""
    tab, run_end, base, nk, hk, ts = nodes
    f_sgn, f_c0, f_c1 = fn.sgn, fn.c0, fn.c1
    i, sa, u0, u1, u2 = at
    q = i
    sq = sa
    uq = u0
    at_run = False
    while q < nk - 1:
        if runs and q > i and run_end[base + q - 1] >= 0 and base + q - 1 >= declined:
            at_run = True  # a run starts with this cell
            break
        sbq = q * hk - ts
        wq = tab[base + q, fr]
        hq = sbq - sq
        clear = True
        for j in range(nfast):
            fa = f_sgn[j] * uq + f_c0[j] + f_c1[j] * sq
            fb = f_sgn[j] * wq + f_c0[j] + f_c1[j] * sbq
            if not (fa > tol and fb > tol and min(fa, fb) - 0.125 * Bf * hq * hq > tol):
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
    return (i, sa, u0, u1, u2), at_run


@njit(cache=True, inline="always")
def _table_search(nodes, fn, nf, ph, consts, rows, piece, basis, split_stack):
    """The first root of the group's first function(s) from ``ts`` to the piece's end ``T`` on
    the node table: cleared cells and runs passed, each other cell tested by :func:`_cell` and
    halved at an exact evaluation while undecided (``split_stack`` holds the pending right ends).
    Returns the function found (-1: none), whether a cell stayed undecided, the cell ``(sa, sb)``
    and the function's row values at its ends (``u0, u1`` at ``sa``, ``w0, w1`` at ``sb``), and
    the basis."""
    tab, run_end, base, nk, hk, ts, T = nodes
    table_nodes = (tab, run_end, base, nk, hk, ts)
    fr, nfast, Bf, B3f, tol, dtol, errd = consts
    sigma, lam, root, r1, w, phi = piece
    f_sgn, f_c0, f_c1, f_zero = fn.sgn, fn.c0, fn.c1, fn.zero
    sp_s, sp_v = split_stack
    cc, ss, sn, cs, bc, bs = basis
    # slipping: the relative velocity, searched by runs; runs of cells before `declined` are
    # left to the cell tests
    runs = nfast == 1 and fr == 1
    line = (f_sgn[0], f_c0[0], f_c1[0], tol, dtol, errd)
    declined = -1
    u0 = _row(rows, fr, cc, ss, sn, cs)
    u1 = _row(rows, fr + 1, cc, ss, sn, cs)
    u2 = _row(rows, fr + 2, cc, ss, sn, cs)
    i = min(int(ts / hk) + 1, nk - 1)
    while i < nk - 1 and i * hk <= ts:
        i += 1
    sa = sb = 0.0
    w0 = w1 = w2 = 0.0
    found = -1
    unsure = False
    for j in range(nf):
        unsure = unsure or f_zero[j]
    sp = 0  # pending right ends from splitting undecided cells (exact values)
    while not unsure:
        if sp == 0 and i < nk - 1:
            at = (i, sa, u0, u1, u2)
            while True:
                if runs:
                    at, declined = _pass_runs(table_nodes, line, at, declined)
                at, at_run = _pass_clear_cells(
                    table_nodes, fn, nfast, fr, Bf, tol, runs, declined, at
                )
                if not at_run:
                    break
            i, sa, u0, u1, u2 = at
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
                sg * u0 + c0 + c1 * sa, sg * w0 + c0 + c1 * sb, sg * u1 + c1, sg * w1 + c1,
                sg * u2, sg * w2, Bf, B3f, sb - sa, tol, dtol,
            )  # fmt: skip
            if code == CELL_UNSURE or (code == CELL_ROOT and found >= 0):
                split = True
            elif code == CELL_ROOT:
                found = j
        if split:
            # halve the cell with an exact evaluation at its middle
            found = -1
            sm = 0.5 * (sa + sb)
            if sp == SPLIT_DEPTH or not sa < sm < sb:
                # (a cell one ulp wide cannot be halved: halving it again and again at the
                # same depth never ends)
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
    return found, unsure, (sa, sb, u0, u1, w0, w1), (cc, ss, sn, cs, bc, bs)


@njit(cache=True, inline="always")
def _cell_root(line, cell, tol, B3f, rows, fr, t0, ts, piece, bnd, k, basis):
    """The root of ``line = (sg, c0, c1)``: ``sg*x^(fr) + c0 + c1*s`` in the cell ``cell = (sa,
    sb, u0, u1, w0, w1)`` that holds exactly one, by a bracketed Halley iteration on the closed
    form (``bnd[k]``: the piece's shift coefficients). Returns whether it converged, the root
    and the basis there."""
    sg, c0, c1 = line
    sa, sb, u0, u1, w0, w1 = cell
    sigma, lam, root, r1, w, phi = piece
    cc, ss, sn, cs, bc, bs = basis
    fa = sg * u0 + c0 + c1 * sa
    fb = sg * w0 + c0 + c1 * sb
    da = sg * u1 + c1
    db = sg * w1 + c1
    hc = sb - sa
    # start: one Newton step on the cubic Hermite interpolant from the secant's root (from the
    # far end for a function released at a); more steps cost more than the Halley iterations
    # they save
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
    # the second and later iterates are usually within the shift radius of the last: their basis
    # is shifted from there (their bounds are not needed before the root: taken once, there)
    shift_max = bnd[k, BND_SHIFT_MAX]
    x_b = np.nan  # where the basis values were taken
    chain = 0
    landed = False  # x is the root (the last step's error bound)
    tau = ts + x
    for _it in range(100):
        tau = ts + x
        if abs(x - x_b) <= shift_max and chain < SHIFT_CHAIN:
            cc, ss, sn, cs = _shift_basis(
                x - x_b, bnd[k, BND_SHIFT], bnd[k, BND_SHIFT + 1], bnd[k, BND_SHIFT + 2],
                bnd[k, BND_SHIFT + 3], bnd[k, BND_SHIFT + 4], bnd[k, BND_SHIFT + 5],
                bnd[k, BND_SHIFT + 6], sigma, lam, w, cc, ss, sn, cs,
            )  # fmt: skip
            chain += 1
        else:
            cc, ss, sn, cs, bc, bs = _basis_all(tau, sigma, lam, root, r1, w, phi)
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
            # Halley's error goes as (c2^2 - c3)*e^3 (c_k = f^(k)/(k!*f')): bounded with
            # |f'''| <= B3f, four times over, within t_res, the step lands on the root: only its
            # basis is taken there
            c2 = 0.5 * f2 / d
            landed = 4.0 * (c2 * c2 + B3f / (6.0 * abs(d))) * dx * dx * dx <= t_res
        if hi - lo <= t_res:
            solved = True
            break
        x = xn
    if solved and chain > 0:
        bc, bs = _basis_bounds(tau, sigma, lam, root, r1)
    return solved, x, (cc, ss, sn, cs, bc, bs)
