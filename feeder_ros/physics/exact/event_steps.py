"""The event steps of the loops (:mod:`.global_loop`, :mod:`.group_march`): the carrier's mode
on the switching surface and its state after its own event, the event log, a group's lead part
and its exit, the end-of-piece group update, the event functions (the carrier's, a sticking or
slipping group's, the shared stick limits), the phase a group takes at its own event, the merge
of groups that stick with the same friction, and the stuck counter.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import numpy as np
from numba import njit

from feeder_ros.physics.exact.layout import (
    EV_BRANCH,
    EV_SLIDE_END,
    EV_SLIDE_START,
    F_BRANCH,
    F_EXIT,
    F_RELVEL,
    F_SLIDE_BWD,
    F_SLIDE_FWD,
    F_STICK_DOWN,
    F_STICK_UP,
    SLIP_BACKWARD,
    SLIP_FORWARD,
    STICK,
)


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


@njit(cache=True, inline="always")
def _carrier_event(kind, switch, mode, x, v, F, dF, F0, m, kf, kb):
    """The carrier's state ``x``, ``v`` and mode after its own event of kind ``kind``, and the
    event to log (``EV_*``, -1 for none). At a stiffness branch (F_BRANCH) the switching variable
    is exactly zero and the new mode follows the branch's sign, or the Filippov sliding mode (0)
    when neither branch moves away (:func:`_classify`); at the end of a sliding hold (F_SLIDE_FWD,
    F_SLIDE_BWD) the carrier leaves on the branch named by the event, at rest."""
    if kind == F_BRANCH:
        if switch == 0:
            new_mode = -mode
            if v == 0.0:
                new_mode = _classify(0, mode, 0.0, 0.0, F, dF, F0, m, kf, kb)
            x = 0.0
        else:
            new_mode = _classify(1, mode, x, 0.0, F, dF, F0, m, kf, kb)
            v = 0.0
        if new_mode == mode:
            return x, v, new_mode, -1
        return x, v, new_mode, EV_SLIDE_START if new_mode == 0.0 else EV_BRANCH
    return x, 0.0, 1.0 if kind == F_SLIDE_FWD else -1.0, EV_SLIDE_END


@njit(cache=True, inline="always")
def _carrier_functions(held, switch, mode, F0, kf, kb, x0, fn):
    """The carrier's event functions at the first slots of a new piece; returns their count. On
    a branch: the switching variable (row ``switch``: x or v) times the mode (F_BRANCH). Held in
    the sliding mode (velocity switching): the sliding bounds ``-(F + F0 - kf*x0)`` (F_SLIDE_FWD)
    and ``F + F0 - kb*x0`` (F_SLIDE_BWD), on the drive force (row 6)."""
    if not held:
        _set_function(0, F_BRANCH, switch, mode, 0.0, fn)
        return 1
    _set_function(0, F_SLIDE_FWD, 6, -1.0, -(F0 - kf * x0), fn)
    _set_function(1, F_SLIDE_BWD, 6, 1.0, F0 - kb * x0, fn)
    return 2


@njit(cache=True, inline="always")
def _set_function(i, kind, row, sgn, c0, fn):
    """Event function ``i`` of the table ``fn``: ``sgn*row(tau) + c0`` of kind ``kind``."""
    f_kind, _f_group, f_row, f_sgn, f_c0, f_c1, f_c2, _f_skip, _f_zero, _f_eval = fn
    f_kind[i] = kind
    f_row[i] = row
    f_sgn[i] = sgn
    f_c0[i] = c0
    f_c1[i] = 0.0
    f_c2[i] = 0.0


@njit(cache=True, inline="always")
def _group_functions(nf, vs, xs, track, gr, fn):
    """The groups' event functions from slot ``nf`` of ``fn`` on, for the global loop's piece (or
    sub-piece after a part event) starting with the carrier at ``xs``, ``vs``; returns the new
    count and the smallest stick limit ``L`` of the sticking groups (inf if none). A sticking
    group takes the carrier's velocity and, once its lead part is at the track end, an exit
    function that is zero at once; a slipping group has its relative velocity and exit
    (:func:`_slip_functions`); the sticking groups share the stick limits of the smallest ``L``
    (:func:`_stick_functions`)."""
    g_L, g_D, _g_mass, g_u, g_y, _g_slip, g_lead, g_phase, g_head = gr
    f_kind, f_group, f_row, f_sgn, f_c0, f_c1, f_c2, _f_skip, _f_zero, _f_eval = fn
    lmin = np.inf
    for g in range(g_L.shape[0]):
        if g_head[g] < 0:
            continue
        if g_phase[g] == STICK:
            g_u[g] = vs
            if g_L[g] < lmin:
                lmin = g_L[g]
            if g_lead[g] + g_y[g] >= track:
                _set_function(nf, F_EXIT, 0, 0.0, track - g_lead[g] - g_y[g], fn)
                f_group[nf] = g
                nf += 1
        else:
            _slip_functions(
                nf, g, track, xs, g_phase, g_D, g_u, g_y, g_lead, f_kind, f_row, f_sgn,
                f_c0, f_c1, f_c2,
            )  # fmt: skip
            f_group[nf] = g
            f_group[nf + 1] = g
            nf += 2
    if lmin < np.inf:
        _stick_functions(nf, lmin, f_kind, f_row, f_sgn, f_c0, f_c1, f_c2)
        nf += 2
    return nf, lmin


@njit(cache=True)
def _merge_into_sticking_group(
    g, g_head, g_phase, g_L, g_D, g_y, g_slip, g_mass, g_lead, m_group, m_next, m_o, m_slip0
):  # fmt: skip
    """Group ``g`` has just stuck: it joins another sticking group of the same friction (their
    futures are identical), if there is one. Its members move to that group's list with their
    offsets and slip totals rebased on it; the mass and lead part are combined and ``g`` is
    emptied (``g_head[g] = -1``)."""
    for h2 in range(g_L.shape[0]):
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
            return
