"""Event ordering for the group march: every group's events merged into one log in time order
(:func:`group_events_in_time_order`), as the global loop would have written it, with a parallel
bucket sort for long logs and a stable argsort for short ones.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

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
