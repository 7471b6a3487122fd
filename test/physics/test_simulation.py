"""Public API of the sharp simulator: shapes, totals, exits, live changes, batch runs, refusals."""

from __future__ import annotations

import math
import re

import numba
import numpy as np
import pytest

from feeder_ros.physics.drive import DriveSchedule
from feeder_ros.physics.group_tables import _output_arrays
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.simulation import (
    EventKind,
    FeederSimulator,
    PartSpec,
    Phase,
    SimulationError,
    limited_threads,
    simulate,
    simulate_carrier,
    simulate_many,
    simulate_parts,
)


@pytest.mark.parametrize(("n", "parts", "march"), [(5, 3, False), (7, 3, True), (4, 0, False)])
def test_output_arrays_are_separate_aligned_views_of_one_block(
    n: int, parts: int, march: bool
) -> None:
    arrays = _output_arrays(n, parts, march)
    shapes = [(n,)] * 4 + [(n, parts)] * 3
    dtypes = [np.float64] * 3 + [np.int8] + [np.float64] * 2 + [np.int8]
    assert [a.shape for a in arrays] == shapes
    assert [a.dtype for a in arrays] == dtypes
    base = arrays[0].base
    while base.base is not None:
        base = base.base
    for a in arrays:
        assert a.size == 0 or a.ctypes.data % 64 == 0
        assert a.flags.writeable
        assert a.flags.f_contiguous if march and a.ndim == 2 else a.flags.c_contiguous
        owner = a.base
        while owner.base is not None:
            owner = owner.base
        assert owner is base
    if march:
        assert np.isnan(arrays[4]).all()
        assert np.isnan(arrays[5]).all()
        assert (arrays[6] == Phase.EXITED).all()
    # no two overlap: each array filled with its own number keeps it
    for i, a in enumerate(arrays):
        a[...] = i + 1
    for i, a in enumerate(arrays):
        assert (a == i + 1).all()


def test_result_shapes_and_sample_times(case_study: FeederParameters) -> None:
    run = simulate(case_study, 0.5, 1000.0, (PartSpec(), PartSpec(0.1), PartSpec(0.2)))
    assert run.t_s.shape == (501,)
    np.testing.assert_array_equal(run.t_s, np.arange(501) / 1000.0)
    assert run.part_x_m.shape == run.part_v_mps.shape == run.part_phase.shape == (501, 3)
    assert run.branch.dtype == np.int8
    assert run.part_phase.dtype == np.int8
    assert run.event_t_s.shape == run.event_kind.shape == run.event_part.shape
    assert np.all(np.diff(run.event_t_s) >= 0.0)
    assert run.carrier_x_m[0] == 0.0
    assert run.carrier_v_mps[0] == 0.0
    assert run.branch[1] == 1  # the first branch is the forward one


@pytest.mark.parametrize("model", ["sharp", "logistic"])
def test_a_duration_a_round_off_short_of_a_sample_time_still_samples_it(model: str) -> None:
    """0.1 - 1e-14 s at 10 Hz: the sample at 0.1 s (a multiple of 1/rate) is simulated, not
    refused and not left unwritten."""
    params = FeederParameters(drive_amplitude_n=40.0, stiffness_model=model)
    run = simulate(params, 0.1 - 1e-14, 10.0)
    np.testing.assert_array_equal(run.t_s, [0.0, 0.1])
    exact = simulate(params, 0.1, 10.0)
    for name in ("carrier_x_m", "carrier_v_mps", "carrier_a_mps2", "part_x_m", "part_v_mps"):
        values = getattr(run, name)
        assert np.all(np.isfinite(values)), name
        np.testing.assert_allclose(values, getattr(exact, name), rtol=1e-9, atol=1e-15)
    assert run.part_x_m[1, 0] != 0.0  # at 40 N the part has moved by 0.1 s


def test_exact_totals_agree_with_the_samples(case_study: FeederParameters) -> None:
    run = simulate(case_study, 2.0, 20_000.0)
    speed = (run.part_x_m[-1, 0] - run.part_x_m[0, 0]) / 2.0
    assert run.mean_part_speed_mps()[0] == pytest.approx(speed, rel=1e-12)
    sampled = np.mean(run.part_phase[:-1, 0] != Phase.STICK)
    assert run.slip_fraction()[0] == pytest.approx(sampled, abs=2e-3)
    assert 0.0 < run.slip_fraction()[0] < 1.0


def test_parts_of_one_friction_sticking_together_share_their_velocity(
    case_study: FeederParameters,
) -> None:
    parts = [PartSpec(0.0), PartSpec(0.05), PartSpec(0.1, static_friction=0.25)]
    run = simulate(case_study, 1.0, 1000.0, parts)
    np.testing.assert_array_equal(run.part_v_mps[:, 0], run.part_v_mps[:, 1])
    np.testing.assert_allclose(run.part_x_m[:, 1] - run.part_x_m[:, 0], 0.05, atol=1e-14)
    assert not np.array_equal(run.part_v_mps[:, 0], run.part_v_mps[:, 2])
    # one event per part for a group event
    starts = run.event_part[run.event_kind == EventKind.SLIP_START]
    assert np.count_nonzero(starts == 0) == np.count_nonzero(starts == 1)


def test_parts_leave_at_the_track_end_in_order() -> None:
    params = FeederParameters(drive_amplitude_n=40.0, drive_frequency_hz=20.0, track_length_m=0.004)
    probe = simulate(params.with_changes(track_length_m=10.0), 2.0, 100.0)
    speed = probe.mean_part_speed_mps()[0]
    assert speed > 1e-3, "this operating point moves parts forward, to the track end"
    parts = [PartSpec(0.003), PartSpec(0.0), PartSpec(0.0015)]
    run = simulate(params, 2.0, 1000.0, parts)
    exits = run.event_part[run.event_kind == EventKind.PART_EXIT]
    assert exits.tolist() == [0, 2, 1]
    assert run.exited_count() == 3
    last = run.part_phase[-1]
    assert np.all(last == Phase.EXITED)
    assert np.all(np.isnan(run.part_x_m[-1]))
    # the exit happens while slipping, at the track end
    for i in range(3):
        t_exit = run.part_exit_t_s[i]
        assert run.part_end_t_s[i] == t_exit
        assert run.part_end_x_m[i] == pytest.approx(
            0.004 + np.interp(t_exit, run.t_s, run.carrier_x_m), abs=1e-5
        )
        # the slip time kept at the exit: the sampled slipping time up to it
        on_track = run.part_phase[:, i] != Phase.EXITED
        sampled = np.count_nonzero(run.part_phase[on_track, i] != Phase.STICK) / 1000.0
        assert run.part_slip_time_s[i] == pytest.approx(sampled, abs=0.02)
        assert 0.1 * t_exit < run.part_slip_time_s[i] < t_exit


def test_spawn_friction_and_parameter_changes_live(case_study: FeederParameters) -> None:
    sim = FeederSimulator(case_study, ())
    sim.advance(0.2)
    index = sim.spawn_part(PartSpec(0.01))
    assert index == 0
    chunk = sim.advance(0.4, [0.2, 0.3, 0.4])
    assert chunk.part_x_m.shape == (3, 1)
    assert chunk.part_x_m[0, 0] == pytest.approx(0.01 + chunk.carrier_x_m[0], abs=1e-15)
    sim.set_part_friction(0.9, 0.8)
    sticky = sim.advance(0.6, np.linspace(0.4, 0.6, 201))
    # a part slipping at the change finishes its slip, then sticks for good (mu_s*g = 8.8 > |a|)
    first_stick = int(np.argmax(sticky.part_phase[:, 0] == Phase.STICK))
    assert first_stick < 100
    assert np.all(sticky.part_phase[first_stick:] == Phase.STICK)
    sim.set_parameters(case_study.with_changes(damping_ns_per_m=500.0))
    damped = sim.advance(3.0, [3.0])
    assert abs(damped.carrier_x_m[0]) < 1e-3
    sim.set_drive(40.0, 0.0, ramp_s=0.1)
    assert sim.drive.values_at(sim.time_s + 0.2) == (40.0, 0.0)
    sim.reset()
    assert sim.time_s == 0.0
    assert sim.part_count == 0


def test_a_refused_live_change_leaves_the_simulator_as_it_was(
    case_study: FeederParameters,
) -> None:
    parts = (PartSpec(0.01), PartSpec(0.02, static_friction=0.15))
    sim = FeederSimulator(case_study.with_changes(coupling="two_way"), parts)
    twin = FeederSimulator(case_study.with_changes(coupling="two_way"), parts)
    sim.advance(0.1)
    twin.advance(0.1)
    before = sim.params
    # the new default kinetic friction exceeds the second part's own static friction
    bad = before.with_changes(static_friction=0.3, kinetic_friction=0.18, part_mass_kg=1.0)
    with pytest.raises(ParameterError, match=r"kinetic_friction=0\.18"):
        sim.set_parameters(bad)
    assert sim.params == before
    for part in (1.5, "1", True, 2, -1):
        with pytest.raises(ParameterError, match=f"part={part!r} is not a part index"):
            sim.set_part_friction(0.3, 0.2, part=part)  # type: ignore[arg-type]
    # the refused calls changed nothing: the run goes on exactly as its twin's
    samples = np.linspace(0.1, 0.5, 41)
    run, reference = sim.advance(0.5, samples), twin.advance(0.5, samples)
    np.testing.assert_array_equal(run.carrier_x_m, reference.carrier_x_m)
    np.testing.assert_array_equal(run.part_x_m, reference.part_x_m)


def test_set_drive_schedules_a_phase_continuous_change(case_study: FeederParameters) -> None:
    sim = FeederSimulator(case_study)
    sim.advance(0.1)
    sim.set_drive(50.0, 20.0, at_time_s=0.15)
    run = sim.advance(0.2, [0.2])
    assert run.event_t_s[run.event_kind == EventKind.DRIVE_CHANGE].tolist() == [0.15]
    with pytest.raises(ParameterError, match=r"at_time_s=0\.1"):
        sim.set_drive(30.0, 1.0, at_time_s=0.1)


def _live_run(
    params: FeederParameters, parts: tuple[PartSpec, ...]
) -> tuple[list[np.ndarray], int]:
    """What a simulator node does under a drive interface that ramps: a command per 20 ms tick
    (each ramped over the tick, some stamped ahead, some repeated at one instant), advancing in
    ticks with samples on a 1 ms grid. Returns the outputs and the longest drive schedule."""
    sim = FeederSimulator(params, parts=parts)
    rng = np.random.default_rng(11)
    out: list[np.ndarray] = []
    longest = 0
    for _ in range(400):
        now = sim.time_s
        ahead = float(rng.choice([0.0, 0.0, 0.007, 0.031]))
        for _ in range(int(rng.choice([1, 1, 2]))):
            sim.set_drive(
                float(rng.uniform(20.0, 26.0)),
                float(rng.uniform(10.0, 60.0)),
                at_time_s=now + ahead,
                ramp_s=float(rng.choice([0.02, 0.0, 0.05])),
            )
            longest = max(longest, len(sim.drive.changes))
        run = sim.advance(now + 0.02, now + np.arange(1, 21) * 1e-3)
        out += [run.carrier_x_m, run.carrier_v_mps, run.carrier_a_mps2, run.branch]
        out += [run.part_x_m, run.part_v_mps, run.part_phase]
        out += [run.event_t_s, run.event_kind, run.event_part]
    return out, longest


def test_a_live_drive_schedule_stays_short_and_the_run_is_unchanged(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import feeder_ros.physics.live_simulator as live_simulator

    params = FeederParameters(damping_ns_per_m=200.0)
    parts = (PartSpec(), PartSpec(position_m=0.01, static_friction=0.25, kinetic_friction=0.2))
    forgetting, short = _live_run(params, parts)
    monkeypatch.setattr(live_simulator, "FORGET_DRIVE_CHANGES_AFTER", 10**9)  # keep everything
    remembering, long = _live_run(params, parts)
    assert long > 400  # every command stays in the schedule
    assert short <= 16  # (the threshold, 8, and the changes of one tick)
    assert len(forgetting) == len(remembering)
    for a, b in zip(forgetting, remembering, strict=True):
        assert a.dtype == b.dtype
        assert a.tobytes() == b.tobytes()  # bit for bit
    events = np.concatenate(forgetting[8::10])
    changes = np.count_nonzero(events == int(EventKind.DRIVE_CHANGE))
    assert changes > 300
    assert events.size - changes > 300  # (and the parts stick and slip)


def test_simulate_many_agrees_with_single_runs() -> None:
    points = [
        FeederParameters(drive_amplitude_n=a, drive_frequency_hz=f, damping_ns_per_m=10.0)
        for a, f in [(40.0, 29.6), (20.0, 45.0), (0.4, 29.6)]
    ]
    drive = DriveSchedule(35.0, 30.0)
    summary = simulate_many([*points, (points[0], drive)], 2.0)
    singles = [simulate(p, 2.0, 10.0) for p in points]
    singles.append(simulate(points[0], 2.0, 10.0, drive=drive))
    for j, run in enumerate(singles):
        assert summary.mean_part_speed_mps[j] == pytest.approx(
            run.mean_part_speed_mps()[0], rel=1e-9, abs=1e-15
        )
        assert summary.slip_fraction[j] == pytest.approx(run.slip_fraction()[0], abs=1e-12)
    assert summary.slip_fraction[2] == 0.0


def test_limited_threads_caps_the_batch_and_restores_the_count() -> None:
    """A caller sharing the machine (the drive interface at configure) runs a batch on fewer
    threads: the same numbers, and the thread count as it was afterwards, error or not."""
    points = [
        FeederParameters(drive_amplitude_n=a, drive_frequency_hz=f, damping_ns_per_m=10.0)
        for a, f in [(40.0, 29.6), (20.0, 45.0), (30.0, 33.0)]
    ]
    before = numba.get_num_threads()
    full = simulate_many(points, 1.0)
    with limited_threads(1):
        assert numba.get_num_threads() == 1
        one = simulate_many(points, 1.0)
    assert numba.get_num_threads() == before
    np.testing.assert_array_equal(one.mean_part_speed_mps, full.mean_part_speed_mps)
    np.testing.assert_array_equal(one.slip_fraction, full.slip_fraction)
    with limited_threads(before + 5):
        assert numba.get_num_threads() == before  # a cap above the count changes nothing
    with pytest.raises(RuntimeError), limited_threads(1):
        raise RuntimeError("the block failed")
    assert numba.get_num_threads() == before
    for bad in (0, -1, 1.5, True, "2"):
        expected = re.escape(f"thread count must be an integer of at least 1, got {bad!r}")
        with pytest.raises(ValueError, match=expected), limited_threads(bad):  # type: ignore[arg-type]
            pass
    assert numba.get_num_threads() == before


def test_simulate_many_measures_a_window_after_settling() -> None:
    """settle_s: speed and slip fraction over [settle, settle + duration], read off one run's
    exact part position at both ends; a part gone before the window has no speed."""
    point = FeederParameters(drive_amplitude_n=40.0, drive_frequency_hz=29.6, damping_ns_per_m=10.0)
    summary = simulate_many([point], 1.5, settle_s=0.5)
    run = simulate(point, 2.0, 4.0)  # samples every 0.25 s: t = 0.5 is row 2, t = 2.0 row 8
    assert run.t_s[2] == 0.5
    assert run.t_s[8] == 2.0
    window_speed = (run.part_x_m[8, 0] - run.part_x_m[2, 0]) / 1.5
    assert summary.mean_part_speed_mps[0] == pytest.approx(window_speed, rel=1e-9)
    slip_phases = (run.part_phase[:, 0] != 0).any()
    assert slip_phases
    assert 0.0 < summary.slip_fraction[0] <= 1.0
    from_rest = simulate_many([point], 2.0).mean_part_speed_mps[0]
    assert abs(from_rest - window_speed) > 1e-6  # the transient counts without settle_s

    short = point.with_changes(drive_frequency_hz=10.0, drive_amplitude_n=20.0, track_length_m=1e-3)
    gone = simulate_many([short], 1.0, settle_s=0.5)  # forward ~6 mm/s: out within 0.5 s
    assert np.isnan(gone.mean_part_speed_mps[0])
    assert np.isfinite(gone.exit_t_s[0])
    with pytest.raises(ParameterError, match=r"settle_s=-1\.0"):
        simulate_many([point], 1.0, settle_s=-1.0)


@pytest.mark.parametrize("settle_s", [0.0, 0.5])
def test_simulate_many_reports_a_point_the_solver_cannot_run(settle_s: float) -> None:
    """An undamped point driven exactly at its forward branch's natural frequency has no bounded
    closed form: the solver stops at once, and simulate_many names that point (with a settle
    window too, where the run stops in its first leg)."""
    good = FeederParameters(drive_amplitude_n=10.0)
    k = good.forward_stiffness_n_per_m * good.cos_theta
    f_n = math.sqrt(k / good.equivalent_mass_kg) / (2.0 * math.pi)
    resonant = good.with_changes(drive_frequency_hz=f_n)
    with pytest.raises(
        SimulationError,
        match=r"failed at 1 of 2 point\(s\): point 1 \(exact resonance of an undamped branch",
    ):
        simulate_many([good, resonant], 1.0, settle_s=settle_s)


def test_simulate_many_window_ends_at_an_exit_inside_it() -> None:
    """One run per point stops at settle_s on the way: a part leaving during the window is
    measured from settle_s to its exit, as a sampled run of the same point shows."""
    point = FeederParameters(
        drive_amplitude_n=20.0, drive_frequency_hz=10.0, damping_ns_per_m=10.0, track_length_m=4e-3
    )
    summary = simulate_many([point], 1.0, settle_s=0.25)
    exit_t = summary.exit_t_s[0]
    assert 0.25 < exit_t < 1.25
    run = simulate(point, 1.25, 4.0)  # t = 0.25 is row 1
    assert run.t_s[1] == 0.25
    assert run.part_exit_t_s[0] == pytest.approx(exit_t, abs=1e-12)
    # lab position at the exit: the track end plus the carrier's displacement then
    carrier = simulate_carrier(point, exit_t, 1.0 / exit_t)
    assert carrier.t_s[1] == pytest.approx(exit_t, abs=1e-15)
    at_exit = point.track_length_m + carrier.carrier_x_m[1]
    window_speed = (at_exit - run.part_x_m[1, 0]) / (exit_t - 0.25)
    assert summary.mean_part_speed_mps[0] == pytest.approx(window_speed, rel=1e-9)
    # a window that starts after the exit: no speed, the exit time kept
    late = simulate_many([point], 1.0, settle_s=exit_t + 0.01)
    assert np.isnan(late.mean_part_speed_mps[0])
    assert late.exit_t_s[0] == pytest.approx(exit_t, abs=1e-12)


def test_carrier_only_and_parts_helpers(case_study: FeederParameters) -> None:
    heavy = case_study.with_changes(part_mass_kg=2.0)
    carrier = simulate_carrier(heavy, 0.2, 1000.0)
    assert carrier.part_x_m.shape == (201, 0)
    parts = simulate_parts(heavy.with_changes(coupling="two_way"), 0.2, 1000.0)
    np.testing.assert_allclose(parts.carrier_x_m, carrier.carrier_x_m, rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda p: simulate(p, math.nan, 1000.0), "duration_s=nan"),
        (lambda p: simulate(p, 1.0, -5.0), "output_rate_hz=-5.0"),
        (lambda p: simulate(p, 1.0, 0.0), "output_rate_hz=0.0"),
        (lambda p: simulate(p, -1.0, 10.0), "duration_s=-1.0"),
        (lambda p: PartSpec(static_friction=0.1, kinetic_friction=0.2), "kinetic_friction=0.2"),
        (
            lambda p: simulate(p, 1.0, 10.0, (PartSpec(kinetic_friction=0.5),)),
            "kinetic_friction=0.5",
        ),
        (lambda p: PartSpec(mass_kg=-1.0), "mass_kg=-1.0"),
        (lambda p: FeederSimulator(p).advance(math.inf), "t_end_s=inf"),
        (lambda p: FeederSimulator(p).advance(1.0, [0.5, 0.2]), "sorted"),
    ],
)
def test_bad_input_is_refused_with_the_value_named(
    call: object, needle: str, case_study: FeederParameters
) -> None:
    assert callable(call)
    with pytest.raises(ParameterError, match=needle):
        call(case_study)


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"plate_count": math.nan}, "plate_count=nan is not an integer"),
        ({"plate_count": math.inf}, "plate_count=inf is not an integer"),
        ({"plate_count": np.float64(2.5)}, r"plate_count=np.float64\(2.5\) is not an integer"),
        ({"carrier_mass_kg": np.True_}, "carrier_mass_kg=np.True_ is not a number"),
        # each in range, together a stiffness that overflows (ZeroDivisionError before) or a
        # natural frequency the solver cannot resolve (a false "exact resonance" before)
        (
            {"backward_length_m": 1e-120},
            "backward_length_m=1e-120 .* backward natural frequency of inf Hz: it must be > 0 "
            "and at most 1e\\+06 Hz",
        ),
        ({"forward_length_m": 1e-60}, "forward natural frequency of 3.68e\\+89 Hz"),
        ({"plate_thickness_m": 1e-200}, "forward natural frequency of 0 Hz"),
    ],
)
def test_parameters_refused_with_the_value_named(changes: dict[str, object], needle: str) -> None:
    with pytest.raises(ParameterError, match=needle):
        FeederParameters(**changes)  # type: ignore[arg-type]


def test_numpy_scalars_are_numbers() -> None:
    """Values read from arrays (np.float32, np.int64) are taken, as Python numbers."""
    params = FeederParameters(
        carrier_mass_kg=np.float32(0.5), plate_count=np.int64(2), drive_frequency_hz=np.float64(25)
    )
    assert params == FeederParameters(carrier_mass_kg=0.5, plate_count=2, drive_frequency_hz=25.0)
    assert type(params.plate_count) is int
    assert type(params.carrier_mass_kg) is float
    schedule = DriveSchedule(np.float32(30.0), np.int64(2))
    assert schedule.values_at(0.0) == pytest.approx((30.0, 2.0), rel=1e-15)


def test_switching_variable_can_change_mid_run(case_study: FeederParameters) -> None:
    sim = FeederSimulator(case_study)
    sim.advance(0.237)
    sim.set_parameters(case_study.with_changes(stiffness_switch="velocity", damping_ns_per_m=5.0))
    run = sim.advance(0.5, np.linspace(0.24, 0.5, 2601))
    v = run.carrier_v_mps
    assert not np.any((run.branch == 1) & (v < 0.0) | (run.branch == -1) & (v > 0.0))


def test_the_group_march_runs_only_where_it_pays() -> None:
    params = FeederParameters(drive_amplitude_n=40.0)
    parts = [
        PartSpec(0.001 * i, static_friction=0.15 + 0.01 * i, kinetic_friction=0.1) for i in range(8)
    ]
    sim = FeederSimulator(params, parts)
    assert not sim._march_pays(0.01)  # a live tick of 8 groups: the global loop
    assert sim._march_pays(1.0)
    assert not FeederSimulator(params, parts[:3])._march_pays(1000.0)  # too few groups


@pytest.mark.parametrize("parallel_min_groups", [1, 10**9])
def test_many_identical_parts_leave_at_one_instant(parallel_min_groups: int) -> None:
    params = FeederParameters(drive_amplitude_n=40.0, drive_frequency_hz=20.0, track_length_m=0.002)
    parts = [PartSpec(0.001)] * 1500 + [PartSpec(0.0005, static_friction=0.3)] * 3
    sim = FeederSimulator(params, parts)
    sim.parallel_min_groups = parallel_min_groups
    sim.march_min_work_s = 0.0
    run = sim.advance(3.0)
    exits = run.event_t_s[run.event_kind == EventKind.PART_EXIT]
    assert exits.size > 0, "no part reached the track end"
    assert np.count_nonzero(exits == exits[0]) >= 1500


@pytest.mark.parametrize("coupling", ["one_way", "two_way"])
def test_a_part_let_go_at_rest_slips_from_rest_instead_of_sliding_back(coupling: str) -> None:
    """``spawn_part(at_rest=True)``, as the simulator's bowl puts parts down: put down while the
    carrier moves back at its peak speed (about 0.09 m/s at 30 Hz), the part starts at rest in
    the lab and friction pulls it along at mu_d*g; it stays within the carrier's stroke of where
    it was put down. A part given the carrier's velocity (the default) slides back about 5 mm,
    and a later feed 1.5 s on could still find the bowl's exit blocked. Parts let go together
    share one group."""
    params = FeederParameters(
        damping_ns_per_m=200.0,
        drive_frequency_hz=30.0,
        drive_amplitude_n=60.0,
        coupling=coupling,  # type: ignore[arg-type]
    )
    probe = FeederSimulator(params, ())
    settled = probe.advance(3.0, np.linspace(2.9, 3.0, 1001))
    t_peak = float(settled.t_s[np.argmin(settled.carrier_v_mps)])
    sim = FeederSimulator(params, ())
    sim.advance(t_peak)
    _, carrier_v, _ = sim.carrier_state
    assert carrier_v < -0.08
    carried = sim.spawn_part(PartSpec(0.0))
    rested = [sim.spawn_part(PartSpec(0.0), at_rest=True) for _ in range(3)]
    assert sim._g.size == 2  # one sticking group, one group let go at rest
    run = sim.advance(t_peak + 1.0, t_peak + np.arange(0.0, 1.0, 1e-4))
    track = run.part_x_m - run.carrier_x_m[:, None]
    first = rested[0]
    assert run.part_v_mps[0, first] == 0.0
    assert run.part_phase[0, first] == Phase.SLIP_FORWARD
    mu_d_g = params.kinetic_friction * params.gravity_mps2
    assert run.part_v_mps[1:50, first] == pytest.approx(-mu_d_g * (run.t_s[1:50] - t_peak))
    assert track[:, first].min() > -0.001  # within the carrier's stroke (about 0.6 mm)
    assert track[:, carried].min() < -0.004  # carried back by the carrier's momentum
    assert track[-1, first] > 0.005  # and 5 mm on within a second
    assert np.array_equal(track[:, rested[1]], track[:, first], equal_nan=True)
