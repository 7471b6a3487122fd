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
from feeder_ros.physics.exact.records import Groups, Members


@njit(cache=True, inline="always")
def _one_group(L, D, mass):
    """One sticking part as a group of one at track offset 0 (stick and kinetic limits ``L``,
    ``D``): the group record of :func:`advance`, with :func:`_one_member`."""
    return Groups(
        np.array([L]), np.array([D]), np.array([mass]), np.zeros(1), np.zeros(1), np.zeros(1),
        np.zeros(1), np.zeros(1, np.int8), np.zeros(1, np.int64),
    )  # fmt: skip


@njit(cache=True, inline="always")
def _one_member(mass):
    """That group's one member, at offset 0 from it."""
    return Members(
        np.zeros(1, np.int64), np.full(1, -1, np.int64), np.zeros(1), np.array([mass]),
        np.zeros(1), np.full(1, np.nan),
    )  # fmt: skip


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
    # no room for samples, events or recorded pieces: a run writes none (shared, never written);
    # samples: times, carrier x, v, a, branch, parts' x, v, phase; events: times, kinds, parts
    empty = np.zeros(0)
    empty_i8 = np.zeros(0, np.int8)
    empty_2d = np.zeros((0, 1))
    no_samples = (
        empty, empty, empty, empty, empty_i8, empty_2d, empty_2d, np.zeros((0, 1), np.int8),
    )  # fmt: skip
    no_events = (empty, empty_i8, np.zeros(0, np.int64))
    no_pieces = np.zeros((0, PIECE_WIDTH))
    for p in prange(models.shape[0]):
        a = d_offset[p]
        b = d_offset[p + 1]
        gr = _one_group(g_L[p], g_D[p], g_mass[p])
        mb = _one_member(g_mass[p])
        st = states[p].copy()
        cnt = np.zeros(5, np.int64)
        status = STATUS_DONE
        split = 0.0 < t_mid[p] < t_end[p]
        for leg in range(2 if split else 1):
            t_stop = t_mid[p] if split and leg == 0 else t_end[p]
            status = advance(
                models[p], d_start[a:b], d_omega[a:b], d_amp[a:b], d_phase[a:b], d_logged[a:b],
                st, gr.L, gr.D, gr.mass, gr.u, gr.y, gr.slip, gr.lead, gr.phase, gr.head, mb.group,
                mb.next, mb.o, mb.mass, mb.slip0, mb.exit_t, t_stop, *no_samples, *no_events, cnt,
                no_pieces,
            )  # fmt: skip
            out = results_mid if split and leg == 0 else results
            out[p, 0] = status
            if mb.group[0] >= 0:
                out[p, 1] = gr.y[0] + st[S_X]
                out[p, 2] = gr.slip[0] - mb.slip0[0]
            else:
                out[p, 1] = mb.o[0]
                out[p, 2] = mb.slip0[0]
            out[p, 3] = mb.exit_t[0]
            out[p, 4] = st[S_T]
            if status != STATUS_DONE:
                results[p, 0] = status  # the caller checks the final results
                break
            if split and leg == 0 and mb.group[0] < 0:
                # the part left before t_mid: nothing changes after
                for q in range(5):
                    results[p, q] = results_mid[p, q]
                break
