"""The certified root search the event loops share: safe steps, the release of a function that
starts a piece on its zero, the cells of recorded node tables, and per-row bounds.

Every event function is ``sgn*row_r(tau) + c0 + c1*tau + c2*tau^2`` and is kept positive between
events: the stiffness branch (``x*b`` or ``v*b``), the Filippov sliding bounds (velocity switching),
the stick limits ``L -+ a``, the relative velocity of each slipping group and the track end. Roots
are found with provably safe steps: with ``|f''| <= B`` on ``[tau, inf)`` (the homogeneous terms
decay, so the bound at ``tau`` holds for all later times) the lower bound ``f + f'*h - B*h^2/2``
stays positive up to the step ``h*``; the search advances by the smallest ``h*`` of all functions,
so it can never jump over a root, and converges quadratically onto the first root from the safe
side. A second lower bound takes the drive's sinusoid at its worst (``-amplitude``) and bounds only
the homogeneous terms' curvature; the longer of the two safe steps is taken. A function that
starts a piece at zero (just after its own event) is released by the sign of its first
non-vanishing derivative (order 1 to 3).
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit

from feeder_ros.physics.exact.closed_form import _row, _row_bound
from feeder_ros.physics.exact.layout import EPS, NROWS
from feeder_ros.physics.exact.records import BoundRows, Functions


@njit(cache=True, inline="always")
def _safe_step(f, d, B):
    """Largest h with f + d*h - B*h^2/2 > 0 (f > 0): no root of f in [tau, tau + h)."""
    if B <= 0.0:
        if d >= 0.0:
            return np.inf
        return f / (-d)
    disc = math.sqrt(d * d + 2.0 * B * f)
    if d <= 0.0:
        return 2.0 * f / (disc - d)
    return (d + disc) / B


DERIVATIVE_ZERO = 1e-10  # relative size below which a derivative counts as zero on release
REL_FREE = 0  # positive: search from the start
REL_SKIP = 1  # starts on its zero, provably positive from the returned offset on
REL_NEVER = 2  # identically zero (e.g. a carrier at rest without drive): no event
REL_NOW = 3  # at or across its zero, moving out: an event now


@njit(cache=True, inline="always")
def _clearly_free(rows, r, sg, c0, c1, cc, ss, sn, cs, bc, bs):
    """True when the event function is clearly positive at the start: the common case of
    :func:`_release`, decided without the square root against an upper bound of the scale (|P| +
    |Q| for the sinusoid's amplitude). Inlined into the callers, because a call that passes arrays
    costs two atomic reference-count updates per array."""
    f = (
        sg * (rows[r, 0] * cc + rows[r, 1] * ss + rows[r, 2] * sn + rows[r, 3] * cs + rows[r, 4])
        + c0
    )
    upper = abs(rows[r, 0]) * bc + abs(rows[r, 1]) * bs + abs(rows[r, 2]) + abs(rows[r, 3])
    upper = abs(sg) * (upper + abs(rows[r, 4])) + abs(c0)
    return f > 64.0 * EPS * upper and not (sg == 0.0 and c1 == 0.0 and c0 > 0.0)


@njit(cache=True)
def _release(rows, r, sg, c0, c1, c2, T, cc, ss, sn, cs, bc, bs, der):
    """Classify the event function ``sg*row_r + c0 + c1*s + c2*s^2`` at the start ``s = 0``.

    The basis values (cc, ss, sn, cs) and bounds (bc, bs) are those at the start. A function on its
    zero (just after its own event) is released when its first non-vanishing derivative (order 1-3)
    points inward: the Taylor lower bound then proves it positive from the returned offset on.
    """
    if _clearly_free(rows, r, sg, c0, c1, cc, ss, sn, cs, bc, bs):
        return REL_FREE, 0.0
    f = sg * _row(rows, r, cc, ss, sn, cs) + c0
    scale = abs(sg) * _row_bound(rows, r, bc, bs) + abs(c0)
    if scale == 0.0 or (sg == 0.0 and c1 == 0.0 and c0 > 0.0):
        return REL_NEVER, 0.0
    tol = 64.0 * EPS * scale
    if f > tol:
        return REL_FREE, 0.0
    der[0] = f
    top = 5 if r < 6 else 9
    for n in range(1, 4):
        if r + n + 1 > top:
            break
        pd = c1 if n == 1 else (2.0 * c2 if n == 2 else 0.0)
        der[n] = sg * _row(rows, r + n, cc, ss, sn, cs) + pd
        B = abs(sg) * _row_bound(rows, r + n + 1, bc, bs)
        if n == 1:
            B += 2.0 * abs(c2)
        if f >= -tol and der[n] > 0.0:
            s0 = T if B == 0.0 else min(der[n] / B, T)
            q = 0.0
            fact = 1.0
            pw = 1.0
            for j in range(n + 1):
                if j > 0:
                    fact *= j
                    pw *= s0
                q += der[j] * pw / fact
            q -= B * pw * s0 / (fact * (n + 1))
            if q > 2.0 * tol:
                return REL_SKIP, s0
            if s0 == T:
                # the piece ends before the function clears round-off: over all of it, it moves
                # inward (its Taylor lower bound has no root in (0, T]) and stays within
                # round-off of zero, so it has no event here. (An event now would be a false
                # one: e.g. the carrier at rest on the switching surface and a drive change
                # 0.5 ns later flipped its branch back and forth at one instant.)
                return REL_SKIP, T
        # a derivative this close to zero is a tangency (e.g. the carrier leaving the sliding mode
        # with x'' = 0): ignoring its sign only ignores a dip far below round-off of x
        tol_n = DERIVATIVE_ZERO * (abs(sg) * _row_bound(rows, r + n, bc, bs) + abs(pd))
        if der[n] < -tol_n:
            break
    return REL_NOW, 0.0


@njit(cache=True, inline="always")
def _step(f, d, B, f2, B3, h_cap):
    """Safe step for f > 0 with slope d, |f''| <= B on [tau, inf), curvature f2 now, |f'''| <= B3.

    The global quadratic bound gives h1; when h1 limits the search, the local bound
    ``f'' >= f2 - B3*h`` on ``[tau, tau + h]`` usually allows a much longer step.
    """
    h1 = _safe_step(f, d, B)
    if h1 < h_cap:
        h_try = 4.0 * h1
        if d < 0.0:
            h_try = max(h1, 1.25 * f / (-d))
        K = B3 * h_try - f2
        h2 = _safe_step(f, d, K if K > 0.0 else 0.0)
        if h2 > h_try:
            h2 = h_try
        if h2 > h1:
            h1 = h2
    return h1


CELL_NONE = 0  # no root in the cell
CELL_ROOT = 1  # exactly one root inside the cell, the function changes sign across it
CELL_UNSURE = 2  # undecided from the end values: halved, at last searched with certified steps
SPLIT_DEPTH = 6  # halvings of an undecided cell before the certified search takes over


@njit(cache=True, inline="always")
def _cell(fa, fb, da, db, ca, cb, B, B3, h, tol, dtol):
    """Roots in the cell ``(a, a + h]`` of a function with values ``fa, fb``, slopes ``da, db``
    and curvatures ``ca, cb`` at its ends, ``|f''| <= B`` and ``|f'''| <= B3`` on it.

    ``fa <= tol`` means the function was released at ``a`` (just after its own event): it must
    leave its zero with ``da > dtol``. The curvature keeps its sign on the cell when ``|ca + cb| >
    B3*h``; the slope keeps its sign when ``|da + db| > B*h`` (and both have that sign)."""
    if fa > tol and fb > tol and min(fa, fb) - 0.125 * B * h * h > tol:
        return CELL_NONE  # above the chord's lower envelope
    convex = ca + cb > B3 * h
    concave = ca + cb < -B3 * h
    if fa <= tol:  # released at a
        if not da > dtol:
            return CELL_UNSURE
        if fb > tol and (convex or concave or (db > 0.0 and da + db > B * h)):
            # rising from a: convex keeps rising, concave stays above the chord, a slope that
            # stays positive keeps rising
            return CELL_NONE
        if fb < -tol and concave:
            return CELL_ROOT  # up from a, down through the one root of a concave function
        return CELL_UNSURE
    falling = da < 0.0 and db < 0.0 and da + db < -B * h
    rising = da > 0.0 and db > 0.0 and da + db > B * h
    if fb < 0.0:
        return CELL_ROOT if (falling or convex or concave) else CELL_UNSURE
    if fb <= tol:
        return CELL_UNSURE  # at the tolerance on the node: the certified search decides
    if concave or falling or rising or (convex and (da >= 0.0 or db <= 0.0)):
        return CELL_NONE
    return CELL_UNSURE


@njit(cache=True, inline="always")
def _bound_terms(rows, lo, hi, lam, root, r_abs_a, r_abs_b, r_amp, r_R):
    """The certified search's per-row bound data of rows ``lo .. hi-1``, shared by both loops
    and taken once per piece: ``|alpha|`` and ``|beta|`` (the homogeneous coefficients), the
    drive sinusoid's amplitude, and the under-damped amplitude form ``sqrt(alpha^2 +
    (beta/root)^2)`` (inf otherwise). :func:`_bound_of_row` turns them into a row's bound."""
    for r in range(lo, hi):
        r_abs_a[r] = abs(rows[r, 0])
        r_abs_b[r] = abs(rows[r, 1])
        r_amp[r] = math.sqrt(rows[r, 2] * rows[r, 2] + rows[r, 3] * rows[r, 3])
        r_R[r] = np.inf
        if lam < 0.0:
            r_R[r] = math.sqrt(rows[r, 0] ** 2 + (rows[r, 1] / root) ** 2)


@njit(cache=True, inline="always")
def _bound_of_row(rows, r, bc, bs, r_abs_a, r_abs_b, r_amp, r_R):
    """A bound of ``|row r|`` over ``[tau, inf)`` from the basis bounds ``bc, bs`` there and the
    data of :func:`_bound_terms`, shared by both loops. Returns the homogeneous terms' bound (the
    smaller of the coefficient-wise and the amplitude form) and the whole row's (plus the drive's
    amplitude and the constant)."""
    bh = r_abs_a[r] * bc + r_abs_b[r] * bs
    bR = r_R[r] * bc
    hb = bh if bh < bR else bR
    return hb, hb + r_amp[r] + abs(rows[r, 4])


@njit(cache=True, inline="always")
def _certified_step(f, s, sg, c0, c1, c2, r, vals, bnds, h_cap):
    """One function's test at a stop of the certified search, shared by both loops: the event
    function ``f = sg*row_r + c0 + c1*s + c2*s^2`` (``f`` evaluated by the caller) at the local
    time ``s`` of its polynomial, with the rows' values ``vals`` and bounds ``bnds`` there.
    Returns ``(-1.0, 0.0)`` when ``f`` is at or below its round-off (an event now), else the
    safe step of :func:`_step` (at most ``h_cap``) and the slope ``f'``."""
    scale = abs(sg) * bnds[r] + abs(c0) + s * abs(c1)
    scale += s * s * abs(c2)
    if f <= 64.0 * EPS * scale:
        return -1.0, 0.0
    d = sg * vals[r + 1] + c1 + 2.0 * s * c2
    B = abs(sg) * bnds[r + 2] + 2.0 * abs(c2)
    f2 = sg * vals[r + 2] + 2.0 * c2
    return _step(f, d, B, f2, abs(sg) * bnds[r + 3], h_cap), d


@njit(cache=True)
def search_scratch(nfmax):
    """A loop's coefficient rows, event-function table for ``nfmax`` functions, its
    search's bound rows and the release's derivative scratch, all zero."""
    fn = Functions(
        np.zeros(nfmax, np.int64), np.zeros(nfmax, np.int64), np.zeros(nfmax, np.int64),
        np.zeros(nfmax), np.zeros(nfmax), np.zeros(nfmax), np.zeros(nfmax), np.zeros(nfmax),
        np.zeros(nfmax, np.bool_), np.zeros(nfmax, np.bool_),
    )  # fmt: skip
    rows = BoundRows(
        np.zeros(NROWS), np.zeros(NROWS), np.zeros(NROWS), np.zeros(NROWS), np.zeros(NROWS),
        np.zeros(NROWS), np.zeros(NROWS),
    )  # fmt: skip
    return np.zeros((NROWS, 5)), fn, rows, np.zeros(5)
