"""The carrier between two events in closed form: coefficient rows, the homogeneous basis and
its bounds, and exact shifts of the basis.

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
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

from numba import njit

from feeder_ros.physics.exact.layout import NROWS


@njit(cache=True, inline="always")
def _branch_constants(c, m, k):
    """The homogeneous basis's constants of ``m*x'' + c*x' + k*x``: ``sigma = -c/(2m)``,
    ``lambda = sigma^2 - k/m``, ``sqrt(|lambda|)`` and, over-damped, ``r1 = (k/m)/(sigma - g)``."""
    sigma = -c / (2.0 * m)
    lam = sigma * sigma - k / m
    root = math.sqrt(abs(lam))
    r1 = 0.0
    if lam > 0.0:
        r1 = (k / m) / (sigma - root)
    return sigma, lam, root, r1


@njit(cache=True)
def _fill_rows(rows, piece, A, m, c, k, F0, x0, v0, held):
    """Coefficient rows of x, x', ..., x^(5) (rows 0-5) and F, ..., F''' (rows 6-9) of the piece
    with basis constants ``piece = (sigma, lam, root, r1, w, phi)``; False at resonance."""
    sigma, lam, _root, _r1, w, phi = piece
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
def _branch_of_piece(c, m, k, w, phi):
    """A piece's closed-form constants on the stiffness branch ``k`` (mass ``m``, damping ``c``,
    drive rate ``w`` and phase ``phi`` at its start): the basis constants ``(sigma, lam, root,
    r1, w, phi)``, the coefficients of :func:`_shift_basis` and the longest shift it allows."""
    sigma, lam, root, r1 = _branch_constants(c, m, k)
    shift = _shift_coefficients(sigma, lam)
    return (sigma, lam, root, r1, w, phi), shift, _shift_max(sigma, root, w)


@njit(cache=True, inline="always")
def _basis_at(ts, piece):
    """The basis values and bounds (:func:`_basis_all`) at the local time ``ts`` of the piece with
    basis constants ``piece``; at its start from the drive phase alone."""
    sigma, lam, root, r1, w, phi = piece
    if ts == 0.0:
        sn, cs = _sincos(phi)
        bc, bs = _basis_bounds(0.0, sigma, lam, root, r1)
        return 1.0, 0.0, sn, cs, bc, bs
    return _basis_all(ts, sigma, lam, root, r1, w, phi)
