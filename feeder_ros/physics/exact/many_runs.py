"""Many independent runs of :func:`~feeder_ros.physics.exact.global_loop.advance` in parallel
(:func:`advance_many`): one model per point of a sweep or a batch.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import numpy as np
from numba import njit, prange

from feeder_ros.physics.exact.global_loop import advance
from feeder_ros.physics.exact.layout import S_T, S_X, STATUS_DONE
from feeder_ros.physics.exact.recorded_pieces import PIECE_WIDTH


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
