"""Exact event-driven solver of the sharp feeder model (numba kernels).

Between events the carrier obeys a linear ODE with constant coefficients, ``m*x'' + c*x' + k*x =
A*sin(w*tau + phi) + F0`` (``k = K_branch*cos(theta)``; ``F0`` the summed slip reaction of the parts
with two-way coupling), whose solution is written in closed form as

    x(tau) = alpha*C(tau) + beta*S(tau) + P*sin(w*tau + phi) + Q*cos(w*tau + phi) + X0

with the homogeneous basis ``C = e^(sigma*tau)*cos(wd*tau)``, ``S = e^(sigma*tau)*sin(wd*tau)/wd``
(under-damped), ``e^(sigma*tau)*cosh``/``sinh(g*tau)/g`` (over-damped) or ``e^(sigma*tau)``,
``tau*e^(sigma*tau)`` (critical), ``sigma = -c/(2m)``, ``lambda = sigma^2 - k/m`` (``-wd^2`` or
``g^2``). All three satisfy ``C' = sigma*C + lambda*S``, ``S' = sigma*S + C``, so every derivative
of ``x`` is again of that form: the solver keeps a table of coefficient rows (rows 0-5: ``x`` to
``x^(5)``, rows 6-9: the drive force ``F`` to ``F'''``).

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

At each stop the stepping skips the functions proven positive well beyond it (``f_skip``: the
release offset, or the end of a safe step reaching more than 8 steps ahead). With one-way coupling
a part event does not change the carrier, so :func:`advance` continues the same closed-form piece
after it (the part's polynomials are then written in the time since the event) instead of
restarting the carrier.
Output samples on a uniform grid are evaluated from one directly evaluated basis by the exact
shift identities (``C(t+h) = C(h)C(t) + lambda*S(h)S(t)``, ``S(t+h) = S(h)C(t) + C(h)S(t)``, the
drive's angle addition) with tabulated shifts ``j*h`` (no error accumulation), plus a first-order
term for the round-off difference between a sample's time and ``t_base + j*h``. ``_sincos``
shares one argument reduction between sine and cosine (fdlibm kernels, within 1 ulp of libm).

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
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

EPS = 2.220446049250313e-16

# model vector
M_ONEWAY = 0  # carrier mass with one-way coupling (M + M_p + alpha*m)
M_BASE = 1  # carrier mass without parts (M + alpha*m), two-way coupling
DAMPING = 2
K_FWD = 3  # K_f*cos(theta)
K_BWD = 4
TRACK = 5
SWITCH = 6  # 0 displacement, 1 velocity
COUPLING = 7  # 0 one-way, 1 two-way
LOG_EVENTS = 8  # 0/1
MODEL_SIZE = 9

# carrier state vector
S_T = 0
S_X = 1
S_V = 2
S_MODE = 3  # +1 forward branch, -1 backward, 0 held (Filippov sliding, velocity switching only)
S_SEG = 4  # drive segment index
STATE_SIZE = 5

# event kinds (public EventKind mirrors these)
EV_BRANCH = 0
EV_SLIP_START = 1
EV_STICK = 2
EV_REVERSAL = 3
EV_DRIVE = 4
EV_EXIT = 5
EV_SLIDE_START = 6
EV_SLIDE_END = 7

# event-function kinds
F_BRANCH = 0
F_SLIDE_FWD = 1
F_SLIDE_BWD = 2
F_STICK_UP = 3
F_STICK_DOWN = 4
F_RELVEL = 5
F_EXIT = 6

STICK = 0
SLIP_FORWARD = 1
SLIP_BACKWARD = 2
EXITED = -1

STATUS_DONE = 0
STATUS_BUFFER_FULL = 1
STATUS_RESONANCE = 2
STATUS_STUCK = 3

NROWS = 10
N_ROT = 64  # output samples evaluated from one directly evaluated basis by exact shifts


@njit(cache=True)
def _fill_rows(rows, sigma, lam, A, w, phi, m, c, k, F0, x0, v0, held):
    """Coefficient rows of x, x', ..., x^(5) (rows 0-5) and F, ..., F''' (rows 6-9); False at
    resonance."""
    for r in range(NROWS):
        for j in range(5):
            rows[r, j] = 0.0
    if held:
        rows[0, 4] = x0
    else:
        detune = k - m * w * w
        det = detune * detune + (c * w) * (c * w)
        if det <= (1e-13 * k) ** 2:
            return False
        P = A * detune / det
        Q = -A * c * w / det
        X0 = F0 / k
        sp, cp = _sincos(phi)
        al = x0 - (P * sp + Q * cp + X0)
        be = (v0 - w * (P * cp - Q * sp)) - sigma * al
        rows[0, 0] = al
        rows[0, 1] = be
        rows[0, 2] = P
        rows[0, 3] = Q
        rows[0, 4] = X0
        for r in range(1, 6):
            a0 = rows[r - 1, 0]
            b0 = rows[r - 1, 1]
            rows[r, 0] = sigma * a0 + b0
            rows[r, 1] = lam * a0 + sigma * b0
            rows[r, 2] = -w * rows[r - 1, 3]
            rows[r, 3] = w * rows[r - 1, 2]
    rows[6, 2] = A
    for r in range(7, NROWS):
        rows[r, 2] = -w * rows[r - 1, 3]
        rows[r, 3] = w * rows[r - 1, 2]
    return True


# sin and cos sharing one argument reduction (fdlibm's __kernel_sin/__kernel_cos and the
# three-part Cody-Waite reduction of __ieee754_rem_pio2): within 1 ulp, like libm, and about
# half the cost of the two calls; arguments beyond SINCOS_MAX go to libm
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
_INVPIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
_PIO2_1T = 6.07710050650619224932e-11  # pi/2 - _PIO2_1
_PIO2_2 = 6.07710050630396597660e-11  # second 33 bits
_PIO2_2T = 2.02226624879595063154e-21
_PIO2_3 = 2.02226624871116645580e-21  # third 33 bits
_PIO2_3T = 8.47842766036889956997e-32
SINCOS_MAX = 1e5


@njit(cache=True, inline="always")
def _sincos(x):
    """(sin(x), cos(x))."""
    if not abs(x) <= SINCOS_MAX:
        return math.sin(x), math.cos(x)
    fn = math.floor(x * _INVPIO2 + 0.5)
    r = x - fn * _PIO2_1  # exact: fn has at most 17 bits
    w = fn * _PIO2_1T
    y0 = r - w
    if abs(y0) < abs(x) * 1.52587890625e-05:  # more than 16 bits cancelled: second round
        t = r
        w = fn * _PIO2_2
        r = t - w
        w = fn * _PIO2_2T - ((t - r) - w)
        y0 = r - w
        if abs(y0) < abs(x) * 1.7763568394002505e-15:  # more than 49 bits: third round
            t = r
            w = fn * _PIO2_3
            r = t - w
            w = fn * _PIO2_3T - ((t - r) - w)
            y0 = r - w
    y1 = (r - y0) - w
    z = y0 * y0
    zz = z * z
    v = z * y0
    rs = _S2 + z * (_S3 + z * _S4) + z * zz * (_S5 + z * _S6)
    sn = y0 - ((z * (0.5 * y1 - v * rs) - y1) - v * _S1)
    rc = z * (_C1 + z * (_C2 + z * _C3)) + zz * zz * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w1 = 1.0 - hz
    cs = w1 + (((1.0 - w1) - hz) + (z * rc - y0 * y1))
    n = int(fn) & 3
    if n == 0:
        return sn, cs
    if n == 1:
        return cs, -sn
    if n == 2:
        return -sn, -cs
    return -cs, sn


@njit(cache=True, inline="always")
def _basis(tau, sigma, lam, root, r1, w, phi):
    if lam < 0.0:
        e = 1.0 if sigma == 0.0 else math.exp(sigma * tau)
        sh, ch = _sincos(root * tau)
        cc = e * ch
        ss = e * sh / root
    elif lam > 0.0:
        r2 = sigma - root
        if 2.0 * root * tau < 1.0:
            e2 = math.exp(r2 * tau)
            em = math.expm1(2.0 * root * tau)
            cc = e2 * (em + 2.0) * 0.5
            ss = e2 * em / (2.0 * root)
        else:
            e1 = math.exp(r1 * tau)
            e2 = math.exp(r2 * tau)
            cc = 0.5 * (e1 + e2)
            ss = (e1 - e2) / (2.0 * root)
    else:
        e = math.exp(sigma * tau)
        cc = e
        ss = tau * e
    ang = w * tau + phi
    sa, ca = _sincos(ang)
    return cc, ss, sa, ca


@njit(cache=True, inline="always")
def _sup_t_exp(r, tau):
    """sup of t*exp(r*t) over t >= tau, r < 0."""
    tm = -1.0 / r
    if tau >= tm:
        return tau * math.exp(r * tau)
    return tm * math.exp(-1.0)


@njit(cache=True, inline="always")
def _basis_bounds(tau, sigma, lam, root, r1):
    """Bounds of |C| and |S| over [tau, inf)."""
    if lam < 0.0:
        if sigma == 0.0:
            return 1.0, 1.0 / root
        e = math.exp(sigma * tau)
        return e, min(e / root, _sup_t_exp(sigma, tau))
    if lam > 0.0:
        e1 = math.exp(r1 * tau)
        return e1, min(e1 / (2.0 * root), _sup_t_exp(r1, tau))
    return math.exp(sigma * tau), _sup_t_exp(sigma, tau)


@njit(cache=True, inline="always")
def _basis_all(tau, sigma, lam, root, r1, w, phi):
    """:func:`_basis` and :func:`_basis_bounds` together, sharing the exponentials."""
    if lam < 0.0:
        if sigma == 0.0:
            e = 1.0
            bs = 1.0 / root
        else:
            e = math.exp(sigma * tau)
            tm = -1.0 / sigma
            sup = tau * e if tau >= tm else tm * math.exp(-1.0)
            bs = min(e / root, sup)
        sh, ch = _sincos(root * tau)
        cc = e * ch
        ss = e * sh / root
        bc = e
    elif lam > 0.0:
        r2 = sigma - root
        e2 = math.exp(r2 * tau)
        if 2.0 * root * tau < 1.0:
            em = math.expm1(2.0 * root * tau)
            cc = e2 * (em + 2.0) * 0.5
            ss = e2 * em / (2.0 * root)
            e1 = e2 * (em + 1.0)
        else:
            e1 = math.exp(r1 * tau)
            cc = 0.5 * (e1 + e2)
            ss = (e1 - e2) / (2.0 * root)
        tm = -1.0 / r1
        sup = tau * e1 if tau >= tm else tm * math.exp(-1.0)
        bc = e1
        bs = min(e1 / (2.0 * root), sup)
    else:
        e = math.exp(sigma * tau)
        cc = e
        ss = tau * e
        tm = -1.0 / sigma
        bc = e
        bs = tau * e if tau >= tm else tm * math.exp(-1.0)
    ang = w * tau + phi
    sa, ca = _sincos(ang)
    return cc, ss, sa, ca, bc, bs


# a point this close to one whose basis is known (in radians of the piece's fastest rate) gets
# its basis by a shift from there, with Taylor series: exact to round-off (the first term left out
# is below 1e-20), and no exponential or sine is evaluated
SHIFT_RAD = 1e-3
SHIFT_CHAIN = 3  # shifts in a row before a direct evaluation (round-off grows with each shift)


@njit(cache=True, inline="always")
def _shift_coefficients(sigma, lam):
    """The Taylor coefficients of ``C(dt)`` (a2 .. a5) and ``S(dt)`` (b3 .. b5) in
    :func:`_shift_basis` (they depend on the piece only: the group march keeps them in its
    tables)."""
    s2 = sigma * sigma
    a2 = 0.5 * (s2 + lam)
    a3 = sigma * (s2 + 3.0 * lam) / 6.0
    a4 = (s2 * s2 + 6.0 * s2 * lam + lam * lam) / 24.0
    a5 = sigma * (s2 * s2 + 10.0 * s2 * lam + 5.0 * lam * lam) / 120.0
    b3 = (3.0 * s2 + lam) / 6.0
    b4 = sigma * (s2 + lam) / 6.0
    b5 = (5.0 * s2 * s2 + 10.0 * s2 * lam + lam * lam) / 120.0
    return a2, a3, a4, a5, b3, b4, b5


@njit(cache=True, inline="always")
def _shift_max(sigma, root, w):
    """The longest shift :func:`_shift_basis` takes on a piece: SHIFT_RAD of its fastest rate."""
    return SHIFT_RAD / max(abs(sigma) + root, w, 1e-300)


@njit(cache=True, inline="always")
def _shift_basis(dt, a2, a3, a4, a5, b3, b4, b5, sigma, lam, w, cc, ss, sn, cs):
    """The basis ``dt`` later (``|dt| * rate <= SHIFT_RAD``): ``C(t+dt) = C(dt)C(t) +
    lam*S(dt)S(t)``, ``S(t+dt) = S(dt)C(t) + C(dt)S(t)`` (the fundamental solution of ``C' =
    sigma*C + lam*S``, ``S' = sigma*S + C``) and the drive's angle addition, with ``C(dt)``,
    ``S(dt)``, ``sin(w*dt)``, ``cos(w*dt)`` from their Taylor series to the fifth or sixth power
    (the piece's coefficients ``a2 .. b5`` from :func:`_shift_coefficients`)."""
    c1 = 1.0 + dt * (sigma + dt * (a2 + dt * (a3 + dt * (a4 + dt * a5))))
    s1 = dt * (1.0 + dt * (sigma + dt * (b3 + dt * (b4 + dt * b5))))
    x = w * dt
    x2 = x * x
    sw = x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0))
    cw = 1.0 - 0.5 * x2 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0))
    return (
        c1 * cc + lam * s1 * ss,
        s1 * cc + c1 * ss,
        sn * cw + cs * sw,
        cs * cw - sn * sw,
    )


@njit(cache=True, inline="always")
def _row(rows, r, cc, ss, sn, cs):
    return rows[r, 0] * cc + rows[r, 1] * ss + rows[r, 2] * sn + rows[r, 3] * cs + rows[r, 4]


@njit(cache=True, inline="always")
def _row_bound(rows, r, bc, bs):
    return (
        abs(rows[r, 0]) * bc
        + abs(rows[r, 1]) * bs
        + math.sqrt(rows[r, 2] * rows[r, 2] + rows[r, 3] * rows[r, 3])
        + abs(rows[r, 4])
    )


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
        for r in range(6):
            for j in range(5):
                rows[r, j] = pieces[k, P_ROWS + 5 * r + j]
        sigma = pieces[k, P_SIGMA]
        lam = pieces[k, P_LAM]
        root = pieces[k, P_ROOT]
        r1 = pieces[k, P_R1]
        w = pieces[k, P_W]
        phi = pieces[k, P_PHI]
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


@njit(cache=True)
def _classify(switch, mode_prev, x, v, F, dF, F0, m, kf, kb):
    """Carrier mode (+1, -1, 0 = held) for a state on or near the switching surface."""
    if switch == 0:
        if x != 0.0:
            return 1.0 if x > 0.0 else -1.0
        if v != 0.0:
            return 1.0 if v > 0.0 else -1.0
        a = F + F0
        if a != 0.0:
            return 1.0 if a > 0.0 else -1.0
        if dF != 0.0:
            return 1.0 if dF > 0.0 else -1.0
        return 1.0
    if v != 0.0:
        return 1.0 if v > 0.0 else -1.0
    af = (F + F0 - kf * x) / m
    ab = (F + F0 - kb * x) / m
    if af > 0.0 and ab > 0.0:
        return 1.0
    if af < 0.0 and ab < 0.0:
        return -1.0
    if af <= 0.0 <= ab:
        if af == 0.0 and ab == 0.0 and dF != 0.0:
            return 1.0 if dF > 0.0 else -1.0
        return 0.0
    return mode_prev if mode_prev != 0.0 else 1.0


@njit(cache=True)
def check_samples(samples):
    """0 if the sample times are finite and sorted, 1 if one is not finite, 2 if unsorted."""
    prev = -np.inf
    unsorted = False
    for i in range(samples.shape[0]):
        t = samples[i]
        if not math.isfinite(t):
            return 1
        if t < prev:
            unsorted = True
        prev = t
    return 2 if unsorted else 0


@njit(cache=True)
def part_totals(group, offset, slip0, exit_t, start_t, start_x, g_y, g_slip, t, x):
    """Each part's totals now (time ``t``, carrier at ``x``), fresh arrays: start time and lab
    position, end time (exit or now), end lab position, time spent slipping, exit time (nan on
    the track). A part on the track (``group >= 0``) is at ``offset + y`` of its group on the
    carrier and has slipped its group's total minus ``slip0`` (the group's total when it joined);
    a part that left keeps its exit values (``offset`` its lab position, ``slip0`` its slip)."""
    n = group.shape[0]
    end_t = np.empty(n)
    end_x = np.empty(n)
    slip = np.empty(n)
    for i in range(n):
        g = group[i]
        if g >= 0:
            end_t[i] = t
            end_x[i] = offset[i] + g_y[g] + x
            slip[i] = g_slip[g] - slip0[i]
        else:
            end_t[i] = exit_t[i]
            end_x[i] = offset[i]
            slip[i] = slip0[i]
    return start_t[:n].copy(), start_x[:n].copy(), end_t, end_x, slip, exit_t[:n].copy()


@njit(cache=True)
def _log(ev_t, ev_kind, ev_part, counters, t, kind, part):
    n = counters[1]
    ev_t[n] = t
    ev_kind[n] = kind
    ev_part[n] = part
    counters[1] = n + 1


@njit(cache=True)
def _log_group(ev_t, ev_kind, ev_part, counters, t, kind, g, g_head, m_next):
    i = g_head[g]
    while i >= 0:
        _log(ev_t, ev_kind, ev_part, counters, t, kind, i)
        i = m_next[i]


@njit(cache=True)
def _group_lead(g, g_head, m_next, m_o):
    lead = -np.inf
    i = g_head[g]
    while i >= 0:
        if m_o[i] > lead:
            lead = m_o[i]
        i = m_next[i]
    return lead


@njit(cache=True, inline="always")
def _shifted_samples(
    samples, ns, nb, jb, t0, tb, h_nom, rot, cb, sb, snb, csb, sigma, lam, w, rows, held, mode,
    out_cx, out_cv, out_ca, out_cb,
):  # fmt: skip
    """The carrier at samples ``ns .. ns+nb-1``, shifted by ``(jb+1+i)*h_nom`` from the basis
    ``(cb, sb, snb, csb)`` at ``tb`` (the shifts' table ``rot`` is filled up to ``jb+nb``)."""
    r00, r01, r02, r03, r04 = rows[0, 0], rows[0, 1], rows[0, 2], rows[0, 3], rows[0, 4]
    r10, r11, r12, r13, r14 = rows[1, 0], rows[1, 1], rows[1, 2], rows[1, 3], rows[1, 4]
    r20, r21, r22, r23, r24 = rows[2, 0], rows[2, 1], rows[2, 2], rows[2, 3], rows[2, 4]
    if held:  # the carrier at rest: x' = x'' = 0 (the basis values are finite)
        r10 = r11 = r12 = r13 = r14 = r20 = r21 = r22 = r23 = r24 = 0.0
    out_cb[ns : ns + nb] = int(mode)
    # a branch-free loop body. In a stand-alone harness LLVM vectorises it (43 against 84 us per
    # 10,000 samples for the loop that tested ``held`` and stored the branch per sample); inlined
    # into ``advance`` it does not (no packed multiplies there), and the gain is not measurable
    for i in range(nb):
        j = jb + 1 + i
        dt = (samples[ns + i] - t0) - (tb + j * h_nom)
        ch = rot[0, j]
        sh = rot[1, j]
        sw = rot[2, j]
        cw = rot[3, j]
        cr = ch * cb + lam * sh * sb
        sr = sh * cb + ch * sb
        snr = snb * cw + csb * sw
        csr = csb * cw - snb * sw
        cc = cr + dt * (sigma * cr + lam * sr)
        ss = sr + dt * (sigma * sr + cr)
        sn = snr + dt * (w * csr)
        cs = csr - dt * (w * snr)
        out_cx[ns + i] = r00 * cc + r01 * ss + r02 * sn + r03 * cs + r04
        out_cv[ns + i] = r10 * cc + r11 * ss + r12 * sn + r13 * cs + r14
        out_ca[ns + i] = r20 * cc + r21 * ss + r22 * sn + r23 * cs + r24


@njit(cache=True, inline="always")
def _part_samples(
    samples, ns, nb, t0, ts, xs, out_cx, out_cv, g_phase, g_u, g_y, g_D, m_group, m_o, out_px,
    out_pv, out_pp,
):  # fmt: skip
    """The parts at samples ``ns .. ns+nb-1`` (carrier already written there): a sticking group
    moves with the carrier, a slipping one with its constant acceleration ``-+D`` since ``ts``."""
    for j in range(m_group.shape[0]):
        g = m_group[j]
        if g < 0:
            for i in range(ns, ns + nb):
                out_px[i, j] = np.nan
                out_pv[i, j] = np.nan
                out_pp[i, j] = EXITED
            continue
        ph = g_phase[g]
        y = g_y[g]
        o = m_o[j]
        if ph == STICK:
            for i in range(ns, ns + nb):
                out_px[i, j] = o + y + out_cx[i]
                out_pv[i, j] = out_cv[i]
                out_pp[i, j] = ph
        else:
            ap = g_D[g] if ph == SLIP_BACKWARD else -g_D[g]
            u = g_u[g]
            for i in range(ns, ns + nb):
                sk = (samples[i] - t0) - ts
                xk = out_cx[i]
                out_px[i, j] = o + (y + sk * (u + 0.5 * ap * sk) - (xk - xs)) + xk
                out_pv[i, j] = u + ap * sk
                out_pp[i, j] = ph


@njit(cache=True, inline="always")
def _exit_lead(
    g, te, xe, g_y, g_slip, g_mass, g_lead, g_head, m_group, m_next, m_o, m_mass, m_slip0,
    m_exit_t,
):  # fmt: skip
    """The track-end event of group ``g`` at time ``te``, the carrier at ``xe``, shared by both
    loops: the member furthest along (largest offset ``m_o``, the first in list order on a tie)
    leaves. It is unlinked from the group's list and keeps its exit values (``m_slip0`` its slip
    time, ``m_o`` its lab position ``m_o + g_y + xe``, ``m_exit_t`` the time, ``m_group`` -1); the
    group loses its mass and, if members remain, takes its lead again. Returns the part's index
    (the caller logs the exit)."""
    lead_i = -1
    i = g_head[g]
    while i >= 0:
        if lead_i < 0 or m_o[i] > m_o[lead_i]:
            lead_i = i
        i = m_next[i]
    # unlink lead_i
    if g_head[g] == lead_i:
        g_head[g] = m_next[lead_i]
    else:
        i = g_head[g]
        while m_next[i] != lead_i:
            i = m_next[i]
        m_next[i] = m_next[lead_i]
    m_next[lead_i] = -1
    m_slip0[lead_i] = g_slip[g] - m_slip0[lead_i]
    m_exit_t[lead_i] = te
    m_o[lead_i] = m_o[lead_i] + g_y[g] + xe  # lab position at exit
    m_group[lead_i] = -1
    g_mass[g] -= m_mass[lead_i]
    if g_head[g] >= 0:
        g_lead[g] = _group_lead(g, g_head, m_next, m_o)
    return lead_i


@njit(cache=True, inline="always")
def _end_group(g, se, xs, xe, ve, g_phase, g_D, g_u, g_y, g_slip):
    """Group ``g`` at the end of a (sub-)piece, shared by both loops: ``se`` is the time since the
    origin ``ts`` of the part's polynomials, over which the carrier moved from ``xs`` to ``xe``,
    and ``ve`` the carrier's velocity at the end. A sticking group takes the carrier's velocity;
    a slipping one, with the constant acceleration ``+D`` (slipping backward) or ``-D`` (forward),
    moves on the carrier by its own travel less the carrier's, speeds up and adds ``se`` to its
    slip time. The phase itself is left to the event that follows."""
    if g_phase[g] == STICK:
        g_u[g] = ve
    else:
        ap = g_D[g] if g_phase[g] == SLIP_BACKWARD else -g_D[g]
        g_y[g] += se * (g_u[g] + 0.5 * ap * se) - (xe - xs)
        g_u[g] += ap * se
        g_slip[g] += se


@njit(cache=True, inline="always")
def _stick_functions(i, limit, f_kind, f_row, f_sgn, f_c0, f_c1, f_c2):
    """The stick limits of sticking parts at slots ``i`` and ``i + 1`` of the event functions,
    shared by both loops: ``limit - x''`` (F_STICK_UP: the carrier accelerates forward past
    ``limit``, the parts slip backward) and ``limit + x''`` (F_STICK_DOWN). ``limit`` is the
    sticking group's ``L`` in the group march, the smallest ``L`` of the sticking groups in the
    global loop."""
    f_kind[i] = F_STICK_UP
    f_row[i] = 2
    f_sgn[i] = -1.0
    f_c0[i] = limit
    f_c1[i] = 0.0
    f_c2[i] = 0.0
    f_kind[i + 1] = F_STICK_DOWN
    f_row[i + 1] = 2
    f_sgn[i + 1] = 1.0
    f_c0[i + 1] = limit
    f_c1[i + 1] = 0.0
    f_c2[i + 1] = 0.0


@njit(cache=True, inline="always")
def _slip_functions(
    i, g, track, xs, g_phase, g_D, g_u, g_y, g_lead, f_kind, f_row, f_sgn, f_c0, f_c1, f_c2
):  # fmt: skip
    """The event functions of slipping group ``g`` at slots ``i`` and ``i + 1``, shared by both
    loops, in the local time ``s`` since the sub-piece's start (carrier at ``xs``): its relative
    velocity ``s_g*(x' - u) - D*s`` (F_RELVEL; ``s_g`` = +1 slipping backward, -1 forward: the
    part's acceleration is ``s_g*D``) and its distance to the track end ``track - lead - y(s)``,
    ``y(s) = y + u*s + s_g*D*s^2/2 - (x - xs)`` (F_EXIT)."""
    s_g = 1.0 if g_phase[g] == SLIP_BACKWARD else -1.0
    ap = s_g * g_D[g]
    f_kind[i] = F_RELVEL
    f_row[i] = 1
    f_sgn[i] = s_g
    f_c0[i] = -s_g * g_u[g]
    f_c1[i] = -g_D[g]
    f_c2[i] = 0.0
    f_kind[i + 1] = F_EXIT
    f_row[i + 1] = 0
    f_sgn[i + 1] = 1.0
    f_c0[i + 1] = track - g_lead[g] - g_y[g] - xs
    f_c1[i + 1] = -g_u[g]
    f_c2[i + 1] = -0.5 * ap


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


@njit(cache=True, inline="always")
def _new_phase(kind, a, L):
    """The phase a group takes at its own event, shared by both loops: at a stick limit it starts
    slipping, backward at F_STICK_UP (the carrier accelerates forward past the limit) and forward
    at F_STICK_DOWN; where its relative velocity vanishes (F_RELVEL) it sticks when the carrier's
    acceleration ``a`` (with the group on it) is within its limit ``L``, else it reverses,
    slipping against ``a``. ``a`` and ``L`` matter only for F_RELVEL."""
    if kind == F_STICK_UP:
        return SLIP_BACKWARD
    if kind == F_STICK_DOWN:
        return SLIP_FORWARD
    if abs(a) <= L:
        return STICK
    return SLIP_BACKWARD if a > 0.0 else SLIP_FORWARD


STUCK_REPEATS = 1000  # events in a row at one instant (no exit among them): the run is stuck


@njit(cache=True, inline="always")
def _count_repeat(zero_count, repeated, kind):
    """The stuck counter shared by :func:`advance` and :func:`_march_group`. ``zero_count`` is the
    number of events in a row found at the very start of their (sub-)piece, no time having passed
    since the event before; ``repeated`` says the event of kind ``kind`` (an ``F_*`` code) is one
    more such. An exit always progresses (one part fewer) and, like any event after a positive
    time, resets the count. Returns the new count and True when the run is stuck (more than
    ``STUCK_REPEATS`` repeats in a row); the caller then returns ``STATUS_STUCK``."""
    if repeated and kind != F_EXIT:
        zero_count += 1
        return zero_count, zero_count > STUCK_REPEATS
    return 0, False


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


# nogil: a table rebuild in a node's worker thread leaves the executor (and, composed, the
# other nodes) running
@njit(cache=True, parallel=True, nogil=True)
def advance_many(
    models,
    d_start,
    d_omega,
    d_amp,
    d_phase,
    d_logged,
    d_offset,
    states,
    g_L,
    g_D,
    g_mass,
    t_mid,
    t_end,
    results_mid,
    results,
):
    """Many independent runs (one part each, no samples, no event log) in parallel.

    ``models[p]``/``states[p]`` per point, the drive of point ``p`` is
    ``d_*[d_offset[p]:d_offset[p+1]]``. ``results[p]`` = [status, part displacement, slip time,
    exit time (nan), time reached] at ``t_end[p]``; with ``0 < t_mid[p] < t_end[p]`` the run also
    stops at ``t_mid[p]`` on the way, and ``results_mid[p]`` holds the same values there.
    """
    n = models.shape[0]
    for p in prange(n):
        a = d_offset[p]
        b = d_offset[p + 1]
        gl = np.array([g_L[p]])
        gd = np.array([g_D[p]])
        gm = np.array([g_mass[p]])
        gu = np.zeros(1)
        gy = np.zeros(1)
        gs = np.zeros(1)
        glead = np.zeros(1)
        gph = np.zeros(1, np.int8)
        gh = np.zeros(1, np.int64)
        mg = np.zeros(1, np.int64)
        mn = np.full(1, -1, np.int64)
        mo = np.zeros(1)
        mm = np.array([g_mass[p]])
        ms = np.zeros(1)
        me = np.full(1, np.nan)
        st = states[p].copy()
        cnt = np.zeros(5, np.int64)
        empty = np.zeros(0)
        e8 = np.zeros(0, np.int8)
        e2 = np.zeros((0, 1))
        e28 = np.zeros((0, 1), np.int8)
        ei = np.zeros(0, np.int64)
        status = STATUS_DONE
        split = 0.0 < t_mid[p] < t_end[p]
        for leg in range(2 if split else 1):
            t_stop = t_mid[p] if split and leg == 0 else t_end[p]
            status = advance(
                models[p],
                d_start[a:b],
                d_omega[a:b],
                d_amp[a:b],
                d_phase[a:b],
                d_logged[a:b],
                st,
                gl,
                gd,
                gm,
                gu,
                gy,
                gs,
                glead,
                gph,
                gh,
                mg,
                mn,
                mo,
                mm,
                ms,
                me,
                t_stop,
                empty,
                empty,
                empty,
                empty,
                e8,
                e2,
                e2,
                e28,
                empty,
                e8,
                ei,
                cnt,
                np.zeros((0, PIECE_WIDTH)),
            )
            out = results_mid if split and leg == 0 else results
            out[p, 0] = status
            if mg[0] >= 0:
                out[p, 1] = gy[0] + st[S_X]
                out[p, 2] = gs[0] - ms[0]
            else:
                out[p, 1] = mo[0]
                out[p, 2] = ms[0]
            out[p, 3] = me[0]
            out[p, 4] = st[S_T]
            if status != STATUS_DONE:
                results[p, 0] = status  # the caller checks the final results
                break
            if split and leg == 0 and mg[0] < 0:
                # the part left before t_mid: nothing changes after
                for q in range(5):
                    results[p, q] = results_mid[p, q]
                break


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


SORT_CHUNKS = 2  # parallel shares (bucket ranges) of group_events_in_time_order
SORT_SERIAL_BELOW = 4096  # fewer events are sorted by a plain stable argsort


@njit(cache=True)
def _members_by_group(members_before, G):
    """Members of each group in increasing part order: ``member[start[g]:start[g + 1]]``."""
    N = members_before.shape[0]
    start = np.zeros(G + 1, np.int64)
    for i in range(N):
        if members_before[i] >= 0:
            start[members_before[i] + 1] += 1
    for g in range(G):
        start[g + 1] += start[g]
    member = np.empty(start[G], np.int64)
    fill = start[:G].copy()
    for i in range(N):
        g = members_before[i]
        if g >= 0:
            member[fill[g]] = i
            fill[g] += 1
    return start, member


@njit(cache=True, inline="always")
def _put(write, pos, b, out_t, out_kind, out_part, t, kind, part):
    if write:
        q = pos[b]
        out_t[q] = t
        out_kind[q] = kind
        out_part[q] = part
    pos[b] += 1


@njit(cache=True)
def _route_events(
    write, b_lo, b_hi, lo, scale, nb, pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n,
    start, member, exit_t, pos, out_t, out_kind, out_part,
):  # fmt: skip
    """Visit the events of :func:`group_events_in_time_order` in input order and, of those in
    time buckets ``[b_lo, b_hi)``, count them (``pos[b] += 1``) or ``write`` them at ``pos[b]``.
    ``nb == 1``: one bucket, every event."""
    for i in range(pre_t.shape[0]):
        t = pre_t[i]
        b = 0 if nb == 1 else min(int((t - lo) * scale), nb - 1)
        if b_lo <= b < b_hi:
            _put(write, pos, b, out_t, out_kind, out_part, t, pre_kind[i], pre_part[i])
    for own in range(2):  # the group events first, then the own ones (exits)
        for g in range(ev_t.shape[0]):
            for n in range(ev_n[g]):
                p = ev_part[g, n]
                if (p >= 0) != (own == 1):
                    continue
                t = ev_t[g, n]
                b = 0 if nb == 1 else min(int((t - lo) * scale), nb - 1)
                if not b_lo <= b < b_hi:
                    continue
                if own == 1:
                    _put(write, pos, b, out_t, out_kind, out_part, t, ev_kind[g, n], p)
                    continue
                for j in range(start[g], start[g + 1]):
                    i = member[j]
                    if not exit_t[i] <= t:
                        _put(write, pos, b, out_t, out_kind, out_part, t, ev_kind[g, n], i)


def group_events_in_time_order(
    pre_t: np.ndarray,
    pre_kind: np.ndarray,
    pre_part: np.ndarray,
    ev_t: np.ndarray,
    ev_kind: np.ndarray,
    ev_part: np.ndarray,
    ev_n: np.ndarray,
    members_before: np.ndarray,
    exit_t: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One pass's events, one per part, in time order: ``(t, kind, part)``.

    The input, in this order: events ``pre_*`` as they are (the carrier's, the drive's), then
    the per-group event rows of :func:`advance_groups` (by group, then row), then the same rows'
    own events (exits). A group event (``ev_part = -1``) goes to every member the group had at
    the start of the pass (``members_before[i]`` is part ``i``'s group then, -1 for none), in
    increasing part order, except members that had left by then (``exit_t <= t``); an exit
    names its part. The result is that input sorted stably by time (equal times keep the input
    order), as ``np.argsort(t, kind="stable")`` would.

    Plain Python around :func:`_fill_events_in_time_order`: the output and the kernel's bucket
    counts are allocated by numpy, which asks Linux for huge pages on large arrays (numba's
    own allocations fault in every 4 kB page, about 1 us each here).
    """
    G = ev_t.shape[0]
    members = np.bincount(members_before[members_before >= 0], minlength=G)[:G]
    bound = pre_t.size + int(np.dot(ev_n, np.maximum(members, 1)))  # exits: one each
    out_t = np.empty(bound)
    out_kind = np.empty(bound, np.int8)
    out_part = np.empty(bound, np.int64)
    counts = np.empty(bound // 2 + 1, np.int64)
    n = _fill_events_in_time_order(
        pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n, members_before, exit_t,
        out_t, out_kind, out_part, counts,
    )  # fmt: skip
    return out_t[:n], out_kind[:n], out_part[:n]


@njit(cache=True, parallel=True)
def _fill_events_in_time_order(
    pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n, members_before, exit_t,
    out_t, out_kind, out_part, counts,
):  # fmt: skip
    """:func:`group_events_in_time_order` into ``out_*`` (room for every event); returns the
    event count. Many events are spread over time buckets (each thread its own range of
    buckets, visiting the input in order; ``counts``: room for one count per two events) and
    each bucket is sorted, without an index array or gathers. Few events, or non-finite times,
    get a plain stable sort."""
    G = ev_t.shape[0]
    start, member = _members_by_group(members_before, G)
    count_g = np.zeros(G, np.int64)
    lo_g = np.full(G, np.inf)
    hi_g = np.full(G, -np.inf)
    finite_g = np.ones(G, np.bool_)
    for g in prange(G):
        for n in range(ev_n[g]):
            t = ev_t[g, n]
            if not math.isfinite(t):
                finite_g[g] = False
            lo_g[g] = min(lo_g[g], t)
            hi_g[g] = max(hi_g[g], t)
            if ev_part[g, n] >= 0:
                count_g[g] += 1
            else:
                for j in range(start[g], start[g + 1]):
                    if not exit_t[member[j]] <= t:
                        count_g[g] += 1
    n_pre = pre_t.shape[0]
    total = n_pre
    lo = np.inf
    hi = -np.inf
    finite = True
    for i in range(n_pre):
        finite = finite and math.isfinite(pre_t[i])
        lo = min(lo, pre_t[i])
        hi = max(hi, pre_t[i])
    for g in range(G):
        total += count_g[g]
        finite = finite and finite_g[g]
        if ev_n[g] > 0:
            lo = min(lo, lo_g[g])
            hi = max(hi, hi_g[g])
    if total < SORT_SERIAL_BELOW or not finite or not lo < hi:
        _sort_few_events(
            pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n, start, member, exit_t,
            out_t, out_kind, out_part, total,
        )  # fmt: skip
        return total
    nb = total // 2 + 1  # measured best (n and 2n no better): events cluster in time
    scale = nb / (hi - lo)
    C = SORT_CHUNKS
    pos = counts[:nb]
    for c in prange(C):
        b_lo = c * nb // C
        b_hi = (c + 1) * nb // C
        for b in range(b_lo, b_hi):
            pos[b] = 0
        _route_events(
            False, b_lo, b_hi, lo, scale, nb, pre_t, pre_kind, pre_part, ev_t, ev_kind,
            ev_part, ev_n, start, member, exit_t, pos, out_t, out_kind, out_part,
        )  # fmt: skip
    q = 0
    for b in range(nb):  # counts -> starts
        m = pos[b]
        pos[b] = q
        q += m
    for c in prange(C):
        _route_events(
            True, c * nb // C, (c + 1) * nb // C, lo, scale, nb, pre_t, pre_kind, pre_part,
            ev_t, ev_kind, ev_part, ev_n, start, member, exit_t, pos, out_t, out_kind, out_part,
        )  # fmt: skip
    # each bucket's position has moved on to the next one's start: bucket b is [pos[b-1], pos[b])
    for c in prange(C):
        for b in range(c * nb // C, (c + 1) * nb // C):
            s = pos[b - 1] if b > 0 else 0
            if pos[b] - s > 1:
                _sort_events(out_t, out_kind, out_part, s, pos[b])
    return total


@njit(cache=True)
def _sort_few_events(
    pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n, start, member, exit_t,
    out_t, out_kind, out_part, total,
):  # fmt: skip
    """:func:`_fill_events_in_time_order` for few events or non-finite times: the events in
    input order, then one stable sort (serial; outside the parallel kernel, whose array
    expressions numba would turn into parallel loops)."""
    pos = np.zeros(1, np.int64)
    _route_events(
        True, 0, 1, 0.0, 0.0, 1, pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n,
        start, member, exit_t, pos, out_t, out_kind, out_part,
    )  # fmt: skip
    order = np.argsort(out_t[:total], kind="mergesort")
    t = out_t[:total][order]
    kind = out_kind[:total][order]
    part = out_part[:total][order]
    out_t[:total] = t
    out_kind[:total] = kind
    out_part[:total] = part


@njit(cache=True)
def _sort_events(t, kind, part, s, e):
    """Stable sort of the events ``[s, e)`` by time, in place."""
    for j in range(s + 1, e):
        if t[j] < t[j - 1]:
            break
    else:
        return
    if e - s > 32:
        idx = np.argsort(t[s:e], kind="mergesort")
        t[s:e] = t[s:e][idx]
        kind[s:e] = kind[s:e][idx]
        part[s:e] = part[s:e][idx]
        return
    for j in range(s + 1, e):
        tc = t[j]
        kc = kind[j]
        pc = part[j]
        q = j - 1
        while q >= s and t[q] > tc:
            t[q + 1] = t[q]
            kind[q + 1] = kind[q]
            part[q + 1] = part[q]
            q -= 1
        t[q + 1] = tc
        kind[q + 1] = kc
        part[q + 1] = pc


@njit(cache=True)
def stable_time_order(t):
    """``np.argsort(t, kind="stable")`` for event times: ``arange`` for times already in order
    (one pass), else a stable sort. Serial: a few events (a live simulator's tick) never start a
    parallel region, whose worker threads would then spin on the other cores for a while (a
    whole second core at a 1 kHz tick). The chunks of a run come in order, but for a drive change
    at the end of the run logged first; the group march's many events are put in order by
    :func:`group_events_in_time_order`."""
    n = t.shape[0]
    for i in range(1, n):
        if not t[i - 1] <= t[i]:  # out of order, or not finite
            return np.argsort(t, kind="mergesort")
    return np.arange(n)
