"""Output samples and part totals.

Output samples on a uniform grid are evaluated from one directly evaluated basis by the exact
shift identities (``C(t+h) = C(h)C(t) + lambda*S(h)S(t)``, ``S(t+h) = S(h)C(t) + C(h)S(t)``, the
drive's angle addition) with tabulated shifts ``j*h`` (no error accumulation), plus a first-order
term for the round-off difference between a sample's time and ``t_base + j*h``. ``_sincos``
shares one argument reduction between sine and cosine (fdlibm kernels, within 1 ulp of libm).
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit

from feeder_ros.physics.exact.closed_form import _basis, _row
from feeder_ros.physics.exact.layout import EXITED, N_ROT, SLIP_BACKWARD, STICK


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
    # the loop reads and writes views that start at the block: their indices run from 0, so
    # LLVM drops numba's wrap-around of negative indices and vectorises the loop with contiguous
    # loads and stores. Indexed from ``ns`` and ``jb`` (unknown sign) it vectorised with gathers
    # and scatters: the 0.4 N, 1 ms output case ran 4.7 ms per call against 4.0 ms now
    j0 = jb + 1
    rot_c, rot_s, rot_sw, rot_cw = rot[0, j0:], rot[1, j0:], rot[2, j0:], rot[3, j0:]
    times = samples[ns : ns + nb]
    x_out, v_out, a_out = out_cx[ns : ns + nb], out_cv[ns : ns + nb], out_ca[ns : ns + nb]
    for i in range(nb):
        dt = (times[i] - t0) - (tb + (j0 + i) * h_nom)
        ch = rot_c[i]
        sh = rot_s[i]
        sw = rot_sw[i]
        cw = rot_cw[i]
        cr = ch * cb + lam * sh * sb
        sr = sh * cb + ch * sb
        snr = snb * cw + csb * sw
        csr = csb * cw - snb * sw
        cc = cr + dt * (sigma * cr + lam * sr)
        ss = sr + dt * (sigma * sr + cr)
        sn = snr + dt * (w * csr)
        cs = csr - dt * (w * snr)
        x_out[i] = r00 * cc + r01 * ss + r02 * sn + r03 * cs + r04
        v_out[i] = r10 * cc + r11 * ss + r12 * sn + r13 * cs + r14
        a_out[i] = r20 * cc + r21 * ss + r22 * sn + r23 * cs + r24


@njit(cache=True, inline="always")
def _part_samples(samples, ns, nb, start, out_cx, out_cv, gr, mb, parts_out):
    """The parts at samples ``ns .. ns+nb-1`` (carrier already written there): a sticking group
    moves with the carrier, a slipping one with its constant acceleration ``-+D`` since ``ts``
    (``start = (t0, ts, xs)``: the piece's start, the sub-piece's, the carrier there)."""
    t0, ts, xs = start
    _g_L, g_D, _g_mass, g_u, g_y, _g_slip, _g_lead, g_phase, _g_head = gr
    m_group, _m_next, m_o, _m_mass, _m_slip0, _m_exit_t = mb
    out_px, out_pv, out_pp = parts_out
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
def _piece_samples(
    samples, counters, t0, ts, xs, t_stop, last, t_end, h_nom, base, piece, rows, held, mode,
    table, carrier_out, gr, mb, parts_out,
):  # fmt: skip
    """The samples ``samples[counters[0]:]`` before ``t_stop`` (up to ``t_end`` included when the
    piece is the run's last) of the piece that started at ``t0`` (the parts' polynomials start at
    its local time ``ts``, carrier at ``xs``). Samples on the nominal grid ``h_nom`` are shifted
    by the tabulated shifts ``j*h_nom`` (``table``, per branch, filled on demand) from the last
    directly evaluated one, ``base`` = (its local time, shifts since, its basis ``C, S, sin,
    cos``); the others are evaluated directly, the parts (groups ``gr``, members ``mb``) with
    them. Returns the new ``base``; ``counters[0]`` counts the samples written."""
    sigma, lam, root, r1, w, phi = piece
    tb, jb, cb, sb, snb, csb = base
    rot_key, rot, rot_n = table.key, table.rot, table.n
    out_cx, out_cv, out_ca, out_cb = carrier_out
    m_group = mb.group
    n_samples = samples.shape[0]
    ns = counters[0]
    can_rot = h_nom > 0.0 and ns + 1 < n_samples and samples[ns + 1] <= t_stop
    slot = 0 if mode >= 0.0 else 1
    if can_rot and (rot_key[slot, 0] != sigma or rot_key[slot, 1] != lam or rot_key[slot, 2] != w):
        # the shifts by j*h_nom of this basis, filled on demand (cached per branch: the
        # pieces alternate between two parameter sets)
        rot_key[slot, 0] = sigma
        rot_key[slot, 1] = lam
        rot_key[slot, 2] = w
        rot_n[slot] = 1
    # the first-order correction below is exact to round-off for |dt|*omega <= 1e-8
    eps_rec = 1e-8 / (abs(sigma) + root + w + 1e-300)
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
            if m_group.shape[0] > 0:
                _part_samples(samples, ns, nb, (t0, ts, xs), out_cx, out_cv, gr, mb, parts_out)
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
        if m_group.shape[0] > 0:
            _part_samples(samples, ns, 1, (t0, ts, xs), out_cx, out_cv, gr, mb, parts_out)
        ns += 1
    counters[0] = ns
    return tb, jb, cb, sb, snb, csb
