"""The group march's node tables and cell test, and the event expansion and ordering kernels."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from feeder_ros.physics.drive import DriveChange, DriveSchedule
from feeder_ros.physics.exact import closed_form, ordering, recorded_pieces, search
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import EventKind, FeederSimulator, PartSpec, SimulationResult


def _distinct_parts(count: int, seed: int) -> list[PartSpec]:
    rng = np.random.default_rng(seed)
    mu_s = rng.uniform(0.15, 0.3, count)
    mu_d = mu_s * rng.uniform(0.4, 0.9, count)
    return [
        PartSpec(position_m=float(x), static_friction=float(s), kinetic_friction=float(d))
        for x, s, d in zip(rng.uniform(0.0, 0.002, count), mu_s, mu_d, strict=True)
    ]


def _capture_piece_tables(
    monkeypatch: pytest.MonkeyPatch,
) -> list[tuple[np.ndarray, tuple[np.ndarray, ...]]]:
    """Record every ``piece_tables`` call of the group march: (its pieces, its tables)."""
    captured: list[tuple[np.ndarray, tuple[np.ndarray, ...]]] = []
    real = recorded_pieces.piece_tables

    def spy(pieces: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
        out: tuple[np.ndarray, ...] = real(pieces, n)
        captured.append((pieces[:n].copy(), out))
        return out

    monkeypatch.setattr(recorded_pieces, "piece_tables", spy)
    return captured


def test_node_tables_hold_the_carrier_and_bound_it(monkeypatch: pytest.MonkeyPatch) -> None:
    captured = _capture_piece_tables(monkeypatch)
    params = FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=10.0)
    sim = FeederSimulator(params, _distinct_parts(6, 1))
    sim.parallel_min_groups = 1
    sim.march_min_work_s = 0.0
    sim.advance(1.0)
    (pieces, (start, h, tab, bnd, _run_end)) = captured[0]
    n = pieces.shape[0]
    assert n > 10
    assert start[-1] == tab.shape[0]
    times = []
    for p in range(n):
        count = start[p + 1] - start[p]
        assert count >= 2  # no held piece with displacement switching
        local = np.arange(count) * h[p]
        local[-1] = pieces[p, recorded_pieces.P_LEN]
        # nodes at most NODE_RAD of the piece's fastest rate (drive or homogeneous) apart
        sigma, lam, root = (
            pieces[p, recorded_pieces.P_SIGMA],
            pieces[p, recorded_pieces.P_LAM],
            pieces[p, recorded_pieces.P_ROOT],
        )
        natural = np.hypot(sigma, root) if lam < 0.0 else abs(sigma) + root
        rate = max(pieces[p, recorded_pieces.P_W], natural)
        assert rate > 0.0
        assert h[p] * rate <= recorded_pieces.NODE_RAD * (1 + 1e-12)
        if count > 2:  # more than one cell: not needlessly fine either
            assert h[p] * rate > 0.5 * recorded_pieces.NODE_RAD
        times.append(pieces[p, recorded_pieces.P_T0] + local)
        for r in range(recorded_pieces.TAB_WIDTH):
            rows = tab[start[p] : start[p + 1], r]
            assert np.all(np.abs(rows) <= bnd[p, r] * (1 + 1e-12))
    t = np.concatenate(times)
    ref = FeederSimulator(params).advance(1.0, np.maximum.accumulate(t))
    for r, values in enumerate((ref.carrier_x_m, ref.carrier_v_mps, ref.carrier_a_mps2)):
        scale = float(np.max(np.abs(values)))
        np.testing.assert_allclose(tab[:, r], values, rtol=0.0, atol=1e-12 * scale)
    # the jerk column is the slope of the acceleration column
    inner = np.diff(t) > 0
    slope = np.diff(tab[:, 2])[inner] / np.diff(t)[inner]
    mid_jerk = 0.5 * (tab[1:, 3] + tab[:-1, 3])[inner]
    scale = float(np.max(np.abs(tab[:, 3])))
    np.testing.assert_allclose(slope, mid_jerk, rtol=0.0, atol=0.05 * scale)


def test_jerk_runs_keep_their_sign(monkeypatch: pytest.MonkeyPatch) -> None:
    """``run_end`` of the node tables: every cell it marks has the carrier's jerk of one sign on
    it, densely sampled from the closed form, the same sign all along the run, and the run stays
    in its piece; most cells are in runs (the slip search passes them by runs)."""
    captured = _capture_piece_tables(monkeypatch)
    for damping in (0.0, 10.0):
        params = FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=damping)
        sim = FeederSimulator(params, _distinct_parts(6, 1))
        sim.parallel_min_groups = 1
        sim.march_min_work_s = 0.0
        sim.advance(0.5)
    assert len(captured) >= 2
    marked = cells = 0
    for pieces, (start, h, tab, _bnd, run_end) in captured:
        for p in range(pieces.shape[0]):
            rows = (
                pieces[p, recorded_pieces.P_ROWS : recorded_pieces.P_ROWS + 30].reshape(6, 5).copy()
            )
            args = [
                pieces[p, c]
                for c in (
                    recorded_pieces.P_SIGMA,
                    recorded_pieces.P_LAM,
                    recorded_pieces.P_ROOT,
                    recorded_pieces.P_R1,
                    recorded_pieces.P_W,
                    recorded_pieces.P_PHI,
                )
            ]
            a, b = start[p], start[p + 1]
            assert np.all(run_end[b - 1 : b] == -1)  # the last node starts no cell
            for c in range(a, b - 1):
                cells += 1
                e = run_end[c]
                if e < 0:
                    continue
                marked += 1
                assert c < e <= b - 1
                # a run goes on in the next cell's run, or ends at the next node
                following = run_end[c + 1] if c + 1 < b - 1 else -1
                assert e == (following if following >= 0 else c + 1)
                sign = np.sign(tab[c, 3])
                t0 = (c - a) * h[p]
                t1 = pieces[p, recorded_pieces.P_LEN] if c + 1 == b - 1 else (c + 1 - a) * h[p]
                for tau in np.linspace(t0, t1, 41):
                    jerk = closed_form._row(rows, 3, *closed_form._basis(tau, *args))
                    assert np.sign(jerk) == sign, (p, c, tau, jerk)
                assert np.all(np.sign(tab[c : e + 1, 3]) == sign)
    assert cells > 100
    assert marked > 0.8 * cells


def test_jerk_sign_certificate_agrees_with_dense_sampling() -> None:
    """``_jerk_keeps_its_sign`` on random sinusoid-plus-line jerks: a cell it certifies has no
    sign change on a fine grid; cells with a sign change are never certified, and both outcomes
    occur."""
    rng = np.random.default_rng(11)
    s = np.linspace(0.0, 1.0, 2001)
    certified = refused = 0
    for _ in range(4000):
        amp, omega = rng.uniform(0.1, 1.0), rng.uniform(0.5, 6.0)
        coef = (amp, omega, rng.uniform(0, 2 * np.pi), 0.0, rng.uniform(-1.2, 1.2))
        h = rng.uniform(0.05, 1.0)
        values = _wave(coef, s * h, 0)
        sure = recorded_pieces._jerk_keeps_its_sign(
            float(values[0]), float(values[-1]), float(_wave(coef, 0.0, 1)),
            float(_wave(coef, h, 1)), amp * omega**2, h, 0.0, 0.0,
        )  # fmt: skip
        if sure:
            certified += 1
            assert np.all(np.sign(values) == np.sign(values[0]))
        else:
            refused += 1
    assert certified > 500
    assert refused > 500


def _wave(coef: tuple[float, ...], x: np.ndarray | float, d: int) -> np.ndarray:
    """``d``-th derivative of ``amp*sin(omega*x + phi) + offset + slope*x``."""
    amp, omega, phi, slope, offset = coef
    base = amp * omega**d * np.sin(omega * np.asarray(x) + phi + d * np.pi / 2)
    if d == 0:
        return np.asarray(base + offset + slope * np.asarray(x))
    return np.asarray(base + (slope if d == 1 else 0.0))


def test_cell_classification_agrees_with_dense_sampling() -> None:
    """Random sinusoid-plus-line functions on a cell: NONE must have no sign change on a fine
    grid, ROOT exactly one; every outcome occurs."""
    rng = np.random.default_rng(5)
    seen = {search.CELL_NONE: 0, search.CELL_ROOT: 0, search.CELL_UNSURE: 0}
    s = np.linspace(0.0, 1.0, 4001)
    for _ in range(4000):
        amp, omega = rng.uniform(0.1, 1.0), rng.uniform(0.5, 6.0)
        phi, slope = rng.uniform(0, 2 * np.pi), rng.uniform(-1.0, 1.0)
        h = rng.uniform(0.05, 1.0)
        released = rng.random() < 0.2
        offset = -amp * np.sin(phi) if released else rng.uniform(-0.3, 1.2)

        coef = (amp, omega, phi, slope, offset)
        fa, fb = float(_wave(coef, 0.0, 0)), float(_wave(coef, h, 0))
        if released:
            fa = 0.0
        elif fa <= 1e-12:
            continue  # only released functions start on (or below) their zero
        code = search._cell(
            fa,
            fb,
            float(_wave(coef, 0.0, 1)),
            float(_wave(coef, h, 1)),
            float(_wave(coef, 0.0, 2)),
            float(_wave(coef, h, 2)),
            amp * omega**2,
            amp * omega**3,
            h,
            1e-14,
            1e-10,
        )
        seen[code] += 1
        values = _wave(coef, s * h, 0)[1:]  # (a, a + h]
        changes = np.count_nonzero(np.diff(np.sign(values)) != 0) + (values[0] <= 0.0)
        if code == search.CELL_NONE:
            assert np.all(values > 0.0), (coef, h, released)
        elif code == search.CELL_ROOT:
            assert changes == 1, (coef, h, released)
            assert values[-1] < 0.0, (coef, h, released)
    assert min(seen.values()) > 50, seen


def test_cell_passes_a_released_function_whose_slope_stays_positive() -> None:
    """Released at the cell's start and rising all through it (the slope bound from both ends
    stays positive) while its curvature changes sign: no root, decided on the end values alone
    instead of halving the cell."""
    coef = (0.1, 3.0, 0.7, 1.0, -0.1 * np.sin(0.7))  # f' = 1 + 0.3*cos(...) >= 0.7
    h = 1.0
    args = [0.0, float(_wave(coef, h, 0))]
    args += [float(_wave(coef, x, 1)) for x in (0.0, h)]
    args += [float(_wave(coef, x, 2)) for x in (0.0, h)]
    B, B3 = 0.1 * 3.0**2, 0.1 * 3.0**3
    assert abs(args[4] + args[5]) < B3 * h  # neither convex nor concave on the cell
    assert search._cell(*args, B, B3, h, 1e-14, 1e-10) == search.CELL_NONE
    assert np.all(_wave(coef, np.linspace(0.0, h, 1001)[1:], 0) > 0.0)
    # a slope that may turn negative inside the cell is still undecided
    assert search._cell(*args, 4.0, B3, h, 1e-14, 1e-10) == search.CELL_UNSURE


def _expand_reference(
    ev_t: np.ndarray,
    ev_kind: np.ndarray,
    ev_part: np.ndarray,
    ev_n: np.ndarray,
    before: np.ndarray,
    exit_t: np.ndarray,
) -> tuple[list[float], list[int], list[int]]:
    group_rows: list[tuple[float, int, int]] = []
    own_rows: list[tuple[float, int, int]] = []
    for g in range(ev_t.shape[0]):
        members = [i for i in range(before.size) if before[i] == g]
        for n in range(ev_n[g]):
            t = float(ev_t[g, n])
            if ev_part[g, n] >= 0:
                own_rows.append((t, int(ev_kind[g, n]), int(ev_part[g, n])))
            else:
                group_rows += [(t, int(ev_kind[g, n]), i) for i in members if not exit_t[i] <= t]
    rows = group_rows + own_rows
    return [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows]


@pytest.mark.parametrize(
    ("sigma", "lam"),
    [
        (0.0, -(207.0**2)),  # undamped (the paper's case)
        (-13.0, 13.0**2 - 207.0**2),  # under-damped
        (-400.0, 400.0**2 - 207.0**2),  # over-damped
        (-207.0, 0.0),  # critically damped
    ],
)
def test_shifted_basis_equals_the_direct_basis(sigma: float, lam: float) -> None:
    """The Halley iteration's shortcut: the basis a short step away, by Taylor series."""
    root = float(np.sqrt(abs(lam)))
    r1 = (sigma * sigma - lam) / (sigma - root) if lam > 0.0 else 0.0  # sigma + root, as the kernel
    w = 2.0 * np.pi * 31.0
    rate = max(abs(sigma) + root, w)
    rng = np.random.default_rng(7)
    for _ in range(200):
        tau = float(rng.uniform(0.0, 0.05))
        phi = float(rng.uniform(-np.pi, np.pi))
        dt = float(rng.uniform(-1.0, 1.0)) * closed_form.SHIFT_RAD / rate
        here = closed_form._basis(tau, sigma, lam, root, r1, w, phi)
        shifted = closed_form._shift_basis(
            dt, *closed_form._shift_coefficients(sigma, lam), sigma, lam, w, *here
        )
        direct = closed_form._basis(tau + dt, sigma, lam, root, r1, w, phi)
        bc, bs = closed_form._basis_bounds(min(tau, tau + dt), sigma, lam, root, r1)
        for got, want, scale in zip(shifted, direct, (bc, bs, 1.0, 1.0), strict=True):
            assert abs(got - want) <= 1e-14 * scale, (tau, dt, got, want)


def _random_pass(seed: int, G: int, N: int, cap: int, clustered: bool) -> tuple[np.ndarray, ...]:
    """Per-group event rows like a march pass's: each row in time order, group events (part -1)
    and exits; ``clustered``: times on a coarse grid (many equal times across groups)."""
    rng = np.random.default_rng(seed)
    before = rng.integers(-1, G, N)
    exit_t = np.where(rng.random(N) < 0.3, rng.uniform(0, 1, N), np.nan)
    ev_n = rng.integers(0, cap + 1, G)
    times = rng.uniform(0, 1, (G, cap))
    if clustered:
        times = np.round(times * 50.0) / 50.0
    ev_t = np.sort(times, axis=1)
    ev_kind = rng.integers(0, 6, (G, cap)).astype(np.int8)
    ev_part = np.where(rng.random((G, cap)) < 0.2, rng.integers(0, N, (G, cap)), -1)
    pre_t = np.round(rng.uniform(0, 1, 40) * 50.0) / 50.0  # ties with the groups' events
    pre_kind = rng.integers(0, 8, 40).astype(np.int8)
    pre_part = rng.integers(-1, N, 40)
    return pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n, before, exit_t


def _sorted_and_expected(
    args: tuple[np.ndarray, ...],
) -> tuple[tuple[list[float], list[int], list[int]], tuple[list[float], list[int], list[int]]]:
    """The kernel's events for a pass, and the reference: the earlier events, then the
    expansion of the groups' rows, sorted stably by time."""
    pre_t, pre_kind, pre_part, ev_t, ev_kind, ev_part, ev_n, before, exit_t = args
    t, kind, part = ordering.group_events_in_time_order(*args)
    assert (t.dtype, kind.dtype, part.dtype) == (np.float64, np.int8, np.int64)
    rt, rk, rp = _expand_reference(ev_t, ev_kind, ev_part, ev_n, before, exit_t)
    want_t = np.concatenate([pre_t, rt])
    order = np.argsort(want_t, kind="stable")
    want = (
        want_t[order].tolist(),
        np.concatenate([pre_kind, rk])[order].tolist(),
        np.concatenate([pre_part, rp])[order].tolist(),
    )
    return (t.tolist(), kind.tolist(), part.tolist()), want


@pytest.mark.parametrize(
    ("G", "N", "cap", "clustered"),
    [
        (5, 17, 9, False),  # below the bucket sort's size: one stable sort
        (5, 17, 9, True),
        (300, 700, 40, False),  # thousands of events: time buckets sorted in parallel
        (300, 700, 40, True),  # long runs of equal times, across groups and the earlier events
    ],
)
def test_group_events_go_to_the_members_present_in_stable_time_order(
    G: int, N: int, cap: int, clustered: bool
) -> None:
    got, want = _sorted_and_expected(_random_pass(G, G, N, cap, clustered))
    assert got == want
    assert len(want[0]) > 40 + 2 * G  # the earlier events and many of the groups'
    if G > 100:
        assert len(got[0]) >= ordering.SORT_SERIAL_BELOW  # the bucket path ran


def test_group_events_with_a_non_finite_time_get_a_plain_stable_sort() -> None:
    args = _random_pass(4, 300, 700, 40, True)
    args[0][3] = np.inf  # an earlier event; no bucket holds it, it sorts last, like argsort's
    got, want = _sorted_and_expected(args)
    assert got == want
    assert (got[0][-1], got[2][-1]) == (np.inf, args[2][3])


@pytest.mark.parametrize(
    "times",
    [
        np.random.default_rng(1).uniform(0, 10, 5000),
        np.random.default_rng(6).uniform(0, 10, 300),
        np.repeat(np.random.default_rng(2).uniform(0, 1, 40), 300),  # long runs of equal times
        np.concatenate([np.full(100, 3.0), np.linspace(0, 1, 50), np.full(7, 3.0)]),
        np.round(np.random.default_rng(4).normal(0, 1e-3, 3000), 5) + 2.0,  # clustered
        np.full(10, 1.5),
        np.array([2.0]),
        np.zeros(0),
        np.arange(20.0),  # in order already
    ],
)
def test_stable_time_order_equals_a_stable_argsort(times: np.ndarray) -> None:
    assert np.array_equal(ordering.stable_time_order(times), np.argsort(times, kind="stable"))


def test_stable_time_order_falls_back_on_non_finite_times() -> None:
    times = np.array([3.0, np.nan, 1.0, np.inf, 1.0])
    assert np.array_equal(ordering.stable_time_order(times), np.argsort(times, kind="stable"))


def test_only_the_group_event_sort_starts_a_parallel_region() -> None:
    # a parallel region leaves the thread pool's workers spinning on the other cores for a while
    # (a whole second core for a live simulator ticking at 1 kHz): the sort of a run's few
    # chunks is serial; only the group march's events (many) are sorted in parallel
    assert not ordering.stable_time_order.targetoptions.get("parallel")
    assert ordering._fill_events_in_time_order.targetoptions.get("parallel")


def _shared_friction_parts() -> list[PartSpec]:
    """Eight parts of three frictions: groups of several members."""
    rng = np.random.default_rng(11)
    return [
        PartSpec(position_m=float(x), static_friction=float(mu), kinetic_friction=float(mu) / 2)
        for x, mu in zip(rng.uniform(0, 0.002, 8), rng.choice([0.15, 0.2, 0.25], 8), strict=True)
    ]


@pytest.mark.parametrize(
    ("changes", "shared", "pieces_per_pass"),
    [
        ({}, False, 512),
        ({"damping_ns_per_m": 30.0}, False, 512),
        # held pieces (velocity switching): no table there
        ({"stiffness_switch": "velocity", "damping_ns_per_m": 5.0}, False, 512),
        ({"drive_amplitude_n": 12.0}, False, 512),  # near the stick limit: near-miss cells
        ({"drive_amplitude_n": 400.0, "damping_ns_per_m": 1500.0}, False, 512),  # over-damped
        ({"track_length_m": 0.003}, True, 7),  # groups of several members, exits, many passes
    ],
)
def test_table_march_equals_the_global_event_loop(
    changes: dict[str, object], shared: bool, pieces_per_pass: int
) -> None:
    params = FeederParameters(drive_amplitude_n=40.0, track_length_m=0.004).with_changes(**changes)
    specs = _shared_friction_parts() if shared else _distinct_parts(24, 7)
    times = np.arange(2001) / 1000.0
    serial = FeederSimulator(params, specs)
    serial.parallel_min_groups = 10**9
    one = serial.advance(2.0, times)
    table = FeederSimulator(params, specs)
    table.parallel_min_groups = 1
    table.march_min_work_s = 0.0
    table.pieces_per_pass = pieces_per_pass
    two = table.advance(2.0, times)
    assert one.event_t_s.size == two.event_t_s.size > 24
    assert one.exited_count() == two.exited_count()
    if shared:
        assert two.exited_count() > 0
    np.testing.assert_array_equal(one.part_phase, two.part_phase)
    np.testing.assert_allclose(two.part_x_m, one.part_x_m, rtol=0, atol=1e-13)
    np.testing.assert_allclose(two.part_v_mps, one.part_v_mps, rtol=0, atol=1e-11)
    np.testing.assert_allclose(two.part_slip_time_s, one.part_slip_time_s, rtol=0, atol=1e-12)
    a = np.lexsort((one.event_part, one.event_kind, one.event_t_s))
    b = np.lexsort((two.event_part, two.event_kind, two.event_t_s))
    np.testing.assert_array_equal(one.event_kind[a], two.event_kind[b])
    np.testing.assert_array_equal(one.event_part[a], two.event_part[b])
    np.testing.assert_allclose(one.event_t_s[a], two.event_t_s[b], rtol=0, atol=1e-12)
    assert np.all(np.diff(two.event_t_s) >= 0.0)


def test_march_events_read_later_are_those_read_at_once() -> None:
    """The group march's events are put in time order when first read (``EventLog``). Read after
    the simulator has run on (parts leaving in the later chunks, groups merged, many passes) they
    are those read at once; a pickled result carries them."""
    params = FeederParameters(drive_amplitude_n=40.0, track_length_m=0.004)
    specs = _shared_friction_parts() + _distinct_parts(6, 3)

    def simulator() -> FeederSimulator:
        sim = FeederSimulator(params, specs)
        sim.parallel_min_groups = 1
        sim.march_min_work_s = 0.0
        sim.pieces_per_pass = 7
        return sim

    at_once, later = simulator(), simulator()
    chunks = [at_once.advance(t) for t in (1.0, 2.0, 3.0)]
    read = [(r.event_t_s.copy(), r.event_kind.copy(), r.event_part.copy()) for r in chunks]
    unread = [later.advance(t) for t in (1.0, 2.0, 3.0)]
    exits = [int(np.count_nonzero(kind == EventKind.PART_EXIT)) for _, kind, _ in read]
    assert min(exits) > 0, exits  # parts leave in each of the chunks
    for (t, kind, part), result in zip(read, unread, strict=True):
        assert t.size > 100
        np.testing.assert_array_equal(result.event_t_s, t)
        np.testing.assert_array_equal(result.event_kind, kind)
        np.testing.assert_array_equal(result.event_part, part)
        copy = pickle.loads(pickle.dumps(result))
        np.testing.assert_array_equal(copy.event_t_s, t)
        np.testing.assert_array_equal(copy.event_part, part)


def _by_part(result: SimulationResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Events ordered by part, kind, time (simultaneous events may come in either order)."""
    o = np.lexsort((result.event_t_s, result.event_kind, result.event_part))
    return result.event_t_s[o], result.event_kind[o], result.event_part[o]


def _same_events(one: SimulationResult, two: SimulationResult) -> bool:
    (ta, ka, pa), (tb, kb, pb) = _by_part(one), _by_part(two)
    return (
        ta.size == tb.size
        and np.array_equal(ka, kb)
        and np.array_equal(pa, pb)
        and bool(np.all(np.abs(ta - tb) <= 1e-12))
    )


def _events_near(result: SimulationResult, t_s: float) -> list[tuple[int, int]]:
    near = np.abs(result.event_t_s - t_s) <= 1e-15
    kinds, parts = result.event_kind[near].tolist(), result.event_part[near].tolist()
    return sorted(zip(kinds, parts, strict=True))


@pytest.mark.parametrize(("damping", "amplitude"), [(30.0, 30.0), (0.0, 40.0)])
def test_a_drive_change_exactly_at_an_event(damping: float, amplitude: float) -> None:
    """The drive changes at the very instant of an event (a part's or the carrier's), for every
    event of a run.

    This used to stop the table march ("an event repeats at one instant": the event found an ulp
    before the end of a carrier piece left a sub-piece shorter than round-off, or a cell of the
    node table claimed a root on the table's round-off), hang it (a cell one ulp wide halved
    forever), and drop the DRIVE_CHANGE from the global loop's log when the carrier's event
    rounded onto the change. Now both paths finish, each logs the change once, at its time, and
    they agree unless the two paths resolve the tie at the change itself differently (an event
    within round-off of the change found on either side of it)."""
    params = FeederParameters(damping_ns_per_m=damping, drive_amplitude_n=amplitude)
    parts = [
        PartSpec(
            position_m=0.01 * i, static_friction=0.12 + 0.03 * i, kinetic_friction=0.06 + 0.02 * i
        )
        for i in range(6)
    ]
    times = np.arange(301) / 1000.0

    def run(parallel_min_groups: int, drive: DriveSchedule | None) -> SimulationResult:
        sim = FeederSimulator(params, parts, drive)
        sim.parallel_min_groups = parallel_min_groups
        sim.march_min_work_s = 0.0
        return sim.advance(0.3, times)

    base = run(10**9, None)
    events = base.event_t_s
    assert events.size > 100
    assert np.count_nonzero(base.event_kind == EventKind.BRANCH_SWITCH) > 4
    f = params.drive_frequency_hz
    agree = 0
    for t_e in events.tolist():
        change = DriveChange(t_e, 1.01 * f, 1.03 * amplitude)
        drive = DriveSchedule(f, amplitude, (change,))
        one, two = run(10**9, drive), run(1, drive)
        for result in (one, two):
            changes = result.event_t_s[result.event_kind == EventKind.DRIVE_CHANGE]
            assert changes.tolist() == [t_e]
            assert np.all(np.diff(result.event_t_s) >= 0.0)
        if _same_events(one, two):
            agree += 1
            np.testing.assert_array_equal(one.part_phase, two.part_phase)
            np.testing.assert_allclose(two.part_x_m, one.part_x_m, rtol=0, atol=1e-13)
            np.testing.assert_allclose(two.part_v_mps, one.part_v_mps, rtol=0, atol=1e-11)
        else:
            # a tie at the change: the paths differ in the events within round-off of it
            k1, k2 = (_events_near(result, t_e) for result in (one, two))
            assert k1 != k2, f"the paths differ after a drive change at {t_e!r} s, not at it"
    assert agree >= 0.9 * events.size
