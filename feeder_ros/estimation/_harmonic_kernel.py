"""Numba kernel of the harmonic least-squares fit (:mod:`feeder_ros.estimation.carrier_velocity`).

The normal equations of a Fourier basis need no design matrix: every Gram entry is a sum of
``cos((k +- j)*theta)`` or ``sin((k +- j)*theta)``, so the power sums
``S_m = sum_n e^{i*m*theta_n}`` (``m = 0..2K``) give all of them in ``O(N*K)`` instead of
``O(N*K^2)``, single-threaded and allocation-light (a BLAS Gram product costs more and competes for
cores in a busy node).
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)  # other threads of the node run meanwhile
def harmonic_lsq(theta, a, K, beta, stats):
    """Fit ``beta[0] + sum_k beta[k]*cos(k*theta) + beta[K+k]*sin(k*theta)`` to ``a``.

    ``stats`` receives (residual sum of squares, lag-one residual autocovariance sum, centred signal
    sum of squares). Returns 0 on success, 1 if the normal equations are not positive definite.
    """
    N = theta.size
    p = 2 * K + 1
    S_re = np.zeros(2 * K + 1)
    S_im = np.zeros(2 * K + 1)
    b = np.zeros(p)
    mean = 0.0
    for n in range(N):
        mean += a[n]
    mean /= max(N, 1)
    for n in range(N):
        zr = math.cos(theta[n])
        zi = math.sin(theta[n])
        wr = 1.0
        wi = 0.0
        an = a[n]
        for m in range(2 * K + 1):
            S_re[m] += wr
            S_im[m] += wi
            if m <= K:
                if m == 0:
                    b[0] += an
                else:
                    b[m] += an * wr
                    b[K + m] += an * wi
            wr, wi = wr * zr - wi * zi, wr * zi + wi * zr
    G = np.zeros((p, p))
    G[0, 0] = N
    for k in range(1, K + 1):
        G[0, k] = S_re[k]
        G[k, 0] = S_re[k]
        G[0, K + k] = S_im[k]
        G[K + k, 0] = S_im[k]
        for j in range(1, K + 1):
            dk = abs(k - j)
            G[k, j] = 0.5 * (S_re[dk] + S_re[k + j])
            G[K + k, K + j] = 0.5 * (S_re[dk] - S_re[k + j])
            im_jk = S_im[j - k] if j >= k else -S_im[k - j]
            G[k, K + j] = 0.5 * (S_im[k + j] + im_jk)
            G[K + j, k] = G[k, K + j]
    trace = 0.0
    for i in range(p):
        trace += G[i, i]
    ridge = 1e-12 * trace / p
    for i in range(p):
        G[i, i] += ridge
    # Cholesky G = L L^T in place (lower triangle)
    for j in range(p):
        s = G[j, j]
        for k in range(j):
            s -= G[j, k] * G[j, k]
        if s <= 0.0:
            return 1
        d = math.sqrt(s)
        G[j, j] = d
        for i in range(j + 1, p):
            s = G[i, j]
            for k in range(j):
                s -= G[i, k] * G[j, k]
            G[i, j] = s / d
    y = np.zeros(p)
    for i in range(p):
        s = b[i]
        for k in range(i):
            s -= G[i, k] * y[k]
        y[i] = s / G[i, i]
    for i in range(p - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, p):
            s -= G[k, i] * beta[k]
        beta[i] = s / G[i, i]
    rss = 0.0
    cov1 = 0.0
    sig = 0.0
    prev = 0.0
    for n in range(N):
        zr = math.cos(theta[n])
        zi = math.sin(theta[n])
        wr = zr
        wi = zi
        model = beta[0]
        for k in range(1, K + 1):
            model += beta[k] * wr + beta[K + k] * wi
            wr, wi = wr * zr - wi * zi, wr * zi + wi * zr
        r = a[n] - model
        rss += r * r
        if n > 0:
            cov1 += r * prev
        prev = r
        sig += (a[n] - mean) ** 2
    stats[0] = rss
    stats[1] = cov1
    stats[2] = sig
    return 0
