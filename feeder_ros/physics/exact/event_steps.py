"""The event steps both loops (:mod:`.global_loop`, :mod:`.group_march`) share: the carrier's
mode on the switching surface, the event log, a group's lead part and its exit, the end-of-piece
group update, a group's stick and slip event functions, the phase a group takes at its own
event, and the stuck counter.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import numpy as np
from numba import njit

from feeder_ros.physics.exact.layout import (
    F_EXIT,
    F_RELVEL,
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
