"""Recorded carrier pieces (one-way coupling) and their node tables, which every group of a
group-march pass reads (:func:`piece_tables`): node spacing, values of ``x .. x''''`` at the
nodes, per-piece bounds and shift coefficients, and the runs of cells on which the carrier's jerk
keeps its sign.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit

from feeder_ros.physics.exact.closed_form import (
    _basis,
    _basis_bounds,
    _row,
    _row_bound,
    _shift_coefficients,
    _shift_max,
    _sincos,
)
from feeder_ros.physics.exact.layout import EPS

# recorded carrier piece: scalars then rows 0-5 (x .. x^(5)) flattened
P_T0 = 0
P_LEN = 1
P_SIGMA = 2
P_LAM = 3
P_ROOT = 4
P_R1 = 5
P_W = 6
P_PHI = 7
P_MODE = 8
P_XE = 9  # x, x', x'' at the end of the piece
P_VE = 10
P_AE = 11
P_ROWS = 12
PIECE_WIDTH = P_ROWS + 30


@njit(cache=True)
def _record_piece(pieces, k, t0, length, sigma, lam, root, r1, w, phi, mode, rows, xe, ve, ae):
    pieces[k, P_XE] = xe
    pieces[k, P_VE] = ve
    pieces[k, P_AE] = ae
    pieces[k, P_T0] = t0
    pieces[k, P_LEN] = length
    pieces[k, P_SIGMA] = sigma
    pieces[k, P_LAM] = lam
    pieces[k, P_ROOT] = root
    pieces[k, P_R1] = r1
    pieces[k, P_W] = w
    pieces[k, P_PHI] = phi
    pieces[k, P_MODE] = mode
    for r in range(6):
        for j in range(5):
            pieces[k, P_ROWS + 5 * r + j] = rows[r, j]


# node tables of recorded pieces, shared by every group of a pass (see :func:`piece_tables`)
NODE_RAD = 0.25  # node spacing in radians of the piece's fastest rate
NODE_MAX = 4096  # nodes per piece at most
TAB_WIDTH = 5  # x, x', x'', x''', x'''' at a node
# per-piece columns of ``bnd`` after the bounds of x .. x^(5): the start's sin(phi), cos(phi) and
# basis bounds, which every group of a pass needs at the piece's start
BND_SIN_PHI = 6
BND_COS_PHI = 7
BND_BC0 = 8
BND_BS0 = 9
BND_SHIFT = 10  # the piece's coefficients of _shift_basis (a2 .. a5, b3 .. b5: 7 columns)
BND_SHIFT_MAX = 17  # the longest shift SHIFT_RAD allows on the piece
BND_WIDTH = 18


@njit(cache=True)
def _node_count_and_step(pieces, k):
    """(node count, node spacing) of piece ``k``: nodes at ``i*h`` and the last at its end;
    held pieces (Filippov sliding) get none (their groups are searched without a table)."""
    T = pieces[k, P_LEN]
    if pieces[k, P_MODE] == 0.0 or not T > 0.0:
        return 0, 0.0
    sigma = pieces[k, P_SIGMA]
    lam = pieces[k, P_LAM]
    root = pieces[k, P_ROOT]
    # the fastest rate of the drive and of the homogeneous basis (|sigma -+ i*wd| or |sigma| + g)
    natural = math.sqrt(sigma * sigma + root * root) if lam < 0.0 else abs(sigma) + root
    rate = max(pieces[k, P_W], natural)
    cells = 1 if rate == 0.0 else math.ceil(T * rate / NODE_RAD)
    cells = min(max(cells, 1), NODE_MAX - 1)
    return cells + 1, T / cells


@njit(cache=True, inline="always")
def _jerk_keeps_its_sign(ya, yb, da, db, B5, h, tol3, tol4):
    """True when ``x'''`` provably keeps the sign of its end values ``ya, yb`` on a cell of length
    ``h``, from its slopes ``da, db`` there and ``|x^(5)| <= B5``: above the chord's lower
    envelope, or monotone (the slope keeps its sign when ``|da + db| > B5*h``). ``tol3`` and
    ``tol4`` are the round-off of the tabulated ``x'''`` and ``x''''``."""
    if ya < 0.0:
        ya, yb, da, db = -ya, -yb, -da, -db
    if not (ya > tol3 and yb > tol3):
        return False
    if min(ya, yb) - 0.125 * B5 * h * h > tol3:
        return True
    return da * db > 0.0 and abs(da + db) > B5 * h + 2.0 * tol4


@njit(cache=True, inline="always")
def _read_piece(pieces, k, rows):
    """Recorded piece ``k``: its start time, length, basis constants ``(sigma, lam, root, r1, w,
    phi)`` and whether the carrier is held; its coefficient rows are copied to ``rows``."""
    for r in range(6):
        for j in range(5):
            rows[r, j] = pieces[k, P_ROWS + 5 * r + j]
    piece = (
        pieces[k, P_SIGMA], pieces[k, P_LAM], pieces[k, P_ROOT], pieces[k, P_R1], pieces[k, P_W],
        pieces[k, P_PHI],
    )  # fmt: skip
    return pieces[k, P_T0], pieces[k, P_LEN], piece, pieces[k, P_MODE] == 0.0


@njit(cache=True)
def piece_tables(pieces, n_pieces):
    """Node tables of the recorded pieces, shared by all groups: ``(node_start, node_h, tab,
    bnd, run_end)``. Piece ``k`` has nodes ``node_start[k] .. node_start[k + 1] - 1`` at local
    times ``i*node_h[k]`` (the last at the piece's end), ``tab[node] = x .. x''''`` there (exact
    closed form), and ``bnd[k, r]`` bounds ``|x^(r)|`` over the whole piece (r = 0 .. 5); ``bnd[k,
    BND_SIN_PHI:]`` holds the drive phase's sine and cosine and the basis bounds at its start.

    ``run_end[node]`` is for the cell from ``node`` to the next node: -1 unless the carrier's jerk
    ``x'''`` provably keeps one sign on the cell; then the last node of the longest stretch of such
    cells from it (within the piece), all of one sign. On such a run a slipping part's relative
    velocity is convex or concave (its curvature is ``-+x'''``), which decides its roots there
    from a few values (see :func:`_march_group`)."""
    node_start = np.zeros(n_pieces + 1, np.int64)
    node_h = np.zeros(n_pieces)
    for k in range(n_pieces):
        n, h = _node_count_and_step(pieces, k)
        node_start[k + 1] = node_start[k] + n
        node_h[k] = h
    tab = np.empty((node_start[n_pieces], TAB_WIDTH))
    bnd = np.zeros((n_pieces, BND_WIDTH))
    for k in range(n_pieces):  # serial: a pass has few pieces, each costs microseconds
        rows = np.zeros((6, 5))
        _t0, _T, piece, _held = _read_piece(pieces, k, rows)
        sigma, lam, root, r1, w, phi = piece
        bc, bs = _basis_bounds(0.0, sigma, lam, root, r1)
        for r in range(6):
            bnd[k, r] = _row_bound(rows, r, bc, bs)
        bnd[k, BND_SIN_PHI], bnd[k, BND_COS_PHI] = _sincos(phi)
        bnd[k, BND_BC0] = bc
        bnd[k, BND_BS0] = bs
        coefficients = _shift_coefficients(sigma, lam)
        for j in range(7):
            bnd[k, BND_SHIFT + j] = coefficients[j]
        bnd[k, BND_SHIFT_MAX] = _shift_max(sigma, root, w)
        a = node_start[k]
        n = node_start[k + 1] - a
        for i in range(n):
            tau = pieces[k, P_LEN] if i == n - 1 else i * node_h[k]
            cc, ss, sn, cs = _basis(tau, sigma, lam, root, r1, w, phi)
            for r in range(TAB_WIDTH):
                tab[a + i, r] = _row(rows, r, cc, ss, sn, cs)
    run_end = np.full(node_start[n_pieces], -1, np.int64)
    for k in range(n_pieces):
        a = node_start[k]
        n = node_start[k + 1] - a
        tol3 = 64.0 * EPS * bnd[k, 3]
        tol4 = 64.0 * EPS * bnd[k, 4]
        for c in range(n - 2, -1, -1):  # from the end: a cell's run goes on in the next cell's
            h = pieces[k, P_LEN] - c * node_h[k] if c == n - 2 else node_h[k]
            if _jerk_keeps_its_sign(
                tab[a + c, 3], tab[a + c + 1, 3], tab[a + c, 4], tab[a + c + 1, 4],
                bnd[k, 5], h, tol3, tol4,
            ):  # fmt: skip
                # the next cell's run (if any) has the same sign: the cells share the node
                after = run_end[a + c + 1] if c < n - 2 else -1
                run_end[a + c] = after if after >= 0 else a + c + 1
    return node_start, node_h, tab, bnd, run_end
