"""Physics of the exact event-driven solver, checked against independent references and laws."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest

from feeder_ros.physics.drive import DriveChange, DriveSchedule
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.reference import reference_simulate
from feeder_ros.physics.simulation import (
    EventKind,
    EventLog,
    FeederSimulator,
    PartSpec,
    Phase,
    SimulationResult,
    simulate,
    simulate_carrier,
)

RTOL = 1e-9


def assert_close(
    actual: np.ndarray, expected: np.ndarray, scale: float, rtol: float = RTOL
) -> None:
    """scipy-style error: |actual - expected| <= atol + rtol*|expected|, atol = rtol*scale."""
    err = np.abs(actual - expected) / (rtol * scale + rtol * np.abs(expected))
    assert np.nanmax(err, initial=0.0) <= 1.0, f"max scaled error {np.nanmax(err):.3g}"


def assert_same_run(run: SimulationResult, ref: SimulationResult, rtol: float = RTOL) -> None:
    sx = float(np.max(np.abs(ref.carrier_x_m)))
    sv = float(np.max(np.abs(ref.carrier_v_mps)))
    assert_close(run.carrier_x_m, ref.carrier_x_m, sx, rtol)
    assert_close(run.carrier_v_mps, ref.carrier_v_mps, sv, rtol)
    assert np.array_equal(run.branch, ref.branch)
    if run.part_x_m.size:
        spx = max(sx, float(np.nanmax(np.abs(ref.part_x_m))))
        assert_close(run.part_x_m, ref.part_x_m, spx, rtol)
        assert_close(run.part_v_mps, ref.part_v_mps, sv, rtol)
        assert np.array_equal(run.part_phase, ref.part_phase)
    assert np.array_equal(run.event_kind, ref.event_kind)
    assert np.array_equal(run.event_part, ref.event_part)
    np.testing.assert_allclose(run.event_t_s, ref.event_t_s, rtol=0.0, atol=1e-10)


@pytest.mark.parametrize("seed", range(10))
def test_closed_form_matches_dop853_on_random_parameters(
    seed: int, random_params: Callable[..., FeederParameters]
) -> None:
    params = random_params(seed)
    parts = (PartSpec(), PartSpec(position_m=0.01, static_friction=0.3, kinetic_friction=0.05))
    run = simulate(params, 0.06, 2000.0, parts)
    ref = reference_simulate(params, 0.06, 2000.0, parts)
    assert_same_run(run, ref)


@pytest.mark.parametrize("switch", ["displacement", "velocity"])
def test_drive_changes_and_ramps_match_dop853(switch: str) -> None:
    params = FeederParameters(drive_amplitude_n=30.0, stiffness_switch=switch, damping_ns_per_m=5.0)
    drive = DriveSchedule(
        29.6,
        30.0,
        (DriveChange(0.0213, 45.0, 50.0), DriveChange(0.04, 25.0, 10.0, ramp_s=0.0125)),
    )
    run = simulate(params, 0.07, 1000.0, (PartSpec(),), drive)
    ref = reference_simulate(params, 0.07, 1000.0, (PartSpec(),), drive)
    assert_same_run(run, ref)
    assert np.count_nonzero(run.event_kind == EventKind.DRIVE_CHANGE) == 2


@pytest.mark.parametrize("phase_rad", [0.0, 2.99, 4.0])
@pytest.mark.parametrize("gap_s", [5e-10, 1e-12])
def test_a_second_drive_change_within_a_nanosecond_from_rest_matches_dop853(
    gap_s: float, phase_rad: float
) -> None:
    """The carrier at rest on its switching surface as the drive comes on, and a second change
    a nanosecond later (a live simulator got two commands whose stamps differed by the
    nanosecond rounding of its clock). The first piece ends before the carrier has left the
    surface by more than round-off; the solver used to flip its branch back and forth at that
    instant until it gave up, which stopped the simulator node."""
    params = FeederParameters(damping_ns_per_m=200.0)
    start = DriveSchedule(21.5, 0.079, start_phase_rad=phase_rad)  # force >0, 0, <0 at t = 0
    change = DriveChange(gap_s, 21.505, 0.198, ramp_s=0.02)
    drive = start.with_change(change)
    run = simulate(params, 0.025, 1000.0, (PartSpec(),), drive)
    ref = reference_simulate(params, 0.025, 1000.0, (PartSpec(),), drive)
    if phase_rad > math.pi:
        # the force pulls into x < 0 at t = 0: at rest on the surface, the solver starts on
        # the branch the carrier moves into; the reference starts on x >= 0's and switches at
        # t = 0 (its first sample and first event)
        assert (run.branch[0], ref.branch[0]) == (-1, 1)
        assert (ref.event_t_s[0], ref.event_kind[0]) == (0.0, EventKind.BRANCH_SWITCH)
        ref = dataclasses.replace(
            ref,
            branch=np.r_[np.int8(-1), ref.branch[1:]],
            events=EventLog.of(ref.event_t_s[1:], ref.event_kind[1:], ref.event_part[1:]),
        )
    assert_same_run(run, ref)
    assert np.max(np.abs(run.carrier_x_m)) > 1e-8  # (the carrier did get going)
    # live, as the simulator node does it: the second command arrives, then one advance
    sim = FeederSimulator(params, (PartSpec(),), start)
    sim.set_drive(change.frequency_hz, change.amplitude_n, change.time_s, change.ramp_s)
    live = sim.advance(0.025, run.t_s)
    assert_close(live.carrier_x_m, run.carrier_x_m, float(np.max(np.abs(ref.carrier_x_m))))
    assert np.array_equal(live.event_kind, run.event_kind)


def test_velocity_switching_holds_the_carrier_in_the_sliding_mode() -> None:
    params = FeederParameters(drive_amplitude_n=40.0, stiffness_switch="velocity")
    run = simulate(params, 0.3, 1000.0)
    ref = reference_simulate(params, 0.3, 1000.0)
    held = run.branch == 0
    assert np.any(held), "this case is known to enter the Filippov sliding mode"
    assert np.all(run.carrier_v_mps[held] == 0.0)
    x = run.carrier_x_m[held]
    assert np.all(x > 0.0)  # sliding happens only where K_b*x <= F <= K_f*x, i.e. x > 0
    assert EventKind.SLIDING_START in run.event_kind
    assert EventKind.SLIDING_END in run.event_kind
    assert_same_run(run, ref, rtol=1e-8)


def _energy(params: FeederParameters, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    k = np.where(x > 0.0, params.forward_stiffness_n_per_m, params.backward_stiffness_n_per_m)
    return 0.5 * params.equivalent_mass_kg * v**2 + 0.5 * k * params.cos_theta * x**2


def test_undamped_free_carrier_conserves_energy_across_switches() -> None:
    params = FeederParameters(drive_amplitude_n=0.0)
    sim = FeederSimulator(params, (), initial_x_m=0.0, initial_v_mps=0.01)
    run = sim.advance(2.0, np.linspace(0.0, 2.0, 4001))
    e = _energy(params, run.carrier_x_m, run.carrier_v_mps)
    assert np.count_nonzero(run.event_kind == EventKind.BRANCH_SWITCH) > 20
    np.testing.assert_allclose(e, e[0], rtol=1e-12)


def test_work_of_the_drive_and_damping_equals_the_energy_change() -> None:
    params = FeederParameters(drive_amplitude_n=25.0, damping_ns_per_m=30.0)
    rate = 400_000.0
    run = simulate_carrier(params, 0.05, rate)
    force = DriveSchedule(params.drive_frequency_hz, 25.0).force(run.t_s)
    power = (force - params.damping_ns_per_m * run.carrier_v_mps) * run.carrier_v_mps
    # Simpson's rule on an even number of intervals
    h = 1.0 / rate
    work = h / 3.0 * (power[0] + power[-1] + 4 * power[1:-1:2].sum() + 2 * power[2:-1:2].sum())
    e = _energy(params, run.carrier_x_m, run.carrier_v_mps)
    assert math.isclose(e[-1] - e[0], work, rel_tol=1e-7)


@pytest.mark.parametrize("switch", ["displacement", "velocity"])
def test_sharp_carrier_is_homogeneous_in_the_amplitude(switch: str) -> None:
    base = FeederParameters(drive_amplitude_n=2.0, stiffness_switch=switch, damping_ns_per_m=3.0)
    one = simulate_carrier(base, 0.5, 1000.0)
    k = 7.3
    scaled = simulate_carrier(base.with_changes(drive_amplitude_n=2.0 * k), 0.5, 1000.0)
    scale = float(np.max(np.abs(one.carrier_v_mps)))
    assert_close(scaled.carrier_v_mps, k * one.carrier_v_mps, k * scale, rtol=1e-10)
    np.testing.assert_allclose(scaled.event_t_s, one.event_t_s, atol=1e-12)


def test_two_way_coupling_converges_to_one_way() -> None:
    errors = []
    for mass in (1e-1, 1e-3, 1e-5):
        params = FeederParameters(drive_amplitude_n=40.0, part_mass_kg=mass, damping_ns_per_m=5.0)
        one = simulate(params, 0.1, 1000.0)
        two = simulate(params.with_changes(coupling="two_way"), 0.1, 1000.0)
        scale = float(np.max(np.abs(one.carrier_x_m)))
        errors.append(
            max(
                float(np.max(np.abs(two.carrier_x_m - one.carrier_x_m))),
                float(np.max(np.abs(two.part_x_m - one.part_x_m))),
            )
            / scale
        )
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-4
    assert errors[0] > 1e-3  # the coupling is real


def test_part_below_the_stick_limit_moves_exactly_with_the_carrier() -> None:
    params = FeederParameters(drive_amplitude_n=0.4)
    run = simulate(params, 2.0, 1000.0, (PartSpec(position_m=0.1),))
    assert np.max(np.abs(run.carrier_a_mps2)) < params.stick_limit_mps2
    assert np.all(run.part_phase == Phase.STICK)
    assert np.array_equal(run.part_v_mps[:, 0], run.carrier_v_mps)
    np.testing.assert_allclose(run.part_x_m[:, 0] - run.carrier_x_m, 0.1, rtol=0, atol=1e-15)
    assert not np.any(run.event_part >= 0)


def _just_before(times: np.ndarray) -> np.ndarray:
    return np.nextafter(times, -np.inf)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_located_events_are_roots_of_their_event_functions(
    seed: int, random_params: Callable[..., FeederParameters]
) -> None:
    params = random_params(seed, stiffness_switch="displacement", coupling="one_way")
    run = simulate(params, 0.3, 100.0)
    kinds, times, parts = run.event_kind, run.event_t_s, run.event_part
    # sample every event instant from the left (the closed form of the piece that ends there)
    sim = FeederSimulator(params)
    before = sim.advance(0.3, _just_before(times))
    sx = float(np.max(np.abs(run.carrier_x_m)))
    sv = float(np.max(np.abs(run.carrier_v_mps)))
    limit = params.stick_limit_mps2
    for j, kind in enumerate(kinds):
        if kind == EventKind.BRANCH_SWITCH:
            assert np.isclose(before.carrier_x_m[j], 0.0, atol=1e-12 * sx)
        elif kind == EventKind.SLIP_START:
            assert np.isclose(abs(before.carrier_a_mps2[j]), limit, rtol=1e-12)
        elif kind in (EventKind.STICK, EventKind.SLIP_REVERSAL):
            i = parts[j]
            assert np.isclose(before.part_v_mps[j, i], before.carrier_v_mps[j], atol=1e-12 * sv)


@pytest.mark.parametrize("seed", [4, 5, 6, 7])
@pytest.mark.parametrize("switch", ["displacement", "velocity"])
def test_no_root_is_missed_on_a_dense_grid(
    seed: int, switch: str, random_params: Callable[..., FeederParameters]
) -> None:
    params = random_params(seed, stiffness_switch=switch)
    run = simulate(params, 0.2, 200_000.0, (PartSpec(),))
    x, v, a = run.carrier_x_m, run.carrier_v_mps, run.carrier_a_mps2
    s = x if switch == "displacement" else v
    # the branch always agrees with the sign of the switching variable
    inconsistent = (run.branch == 1) & (s < 0) | (run.branch == -1) & (s > 0)
    assert not np.any(inconsistent)
    # the part's phase always agrees with the stick/slip conditions
    sv = float(np.max(np.abs(v)))
    phase, u = run.part_phase[:, 0], run.part_v_mps[:, 0]
    assert np.all(np.abs(a[phase == Phase.STICK]) <= params.stick_limit_mps2 * (1 + 1e-12))
    assert np.all((v - u)[phase == Phase.SLIP_BACKWARD] >= -1e-12 * sv)
    assert np.all((u - v)[phase == Phase.SLIP_FORWARD] >= -1e-12 * sv)
    switches = np.count_nonzero(np.diff(np.sign(s[np.abs(s) > 0])))
    assert switches <= np.count_nonzero(
        np.isin(run.event_kind, [EventKind.BRANCH_SWITCH, EventKind.SLIDING_START])
    )


def test_case_study_natural_frequencies_from_free_vibration() -> None:
    params = FeederParameters(drive_amplitude_n=0.0)
    assert params.forward_natural_frequency_hz == pytest.approx(32.93, abs=0.005)
    assert params.backward_natural_frequency_hz == pytest.approx(6.34, abs=0.005)
    sim = FeederSimulator(params, (), initial_v_mps=1e-3)
    run = sim.advance(1.0)
    switches = run.event_t_s[run.event_kind == EventKind.BRANCH_SWITCH]
    # half a forward period, then half a backward period, alternately
    assert switches[0] == pytest.approx(0.5 / params.forward_natural_frequency_hz, rel=1e-12)
    assert switches[1] - switches[0] == pytest.approx(
        0.5 / params.backward_natural_frequency_hz, rel=1e-12
    )


def test_case_study_no_slip_at_0_4_newton() -> None:
    run = simulate(FeederParameters(drive_amplitude_n=0.4), 5.0, 1000.0)
    assert np.all(run.part_phase == Phase.STICK)


def test_case_study_slips_both_ways_at_40_newton_first_onset_3_ms(
    case_study: FeederParameters,
) -> None:
    run = simulate(case_study, 1.0, 1000.0)
    assert np.any(run.part_phase == Phase.SLIP_FORWARD)
    assert np.any(run.part_phase == Phase.SLIP_BACKWARD)
    onset = run.event_t_s[run.event_kind == EventKind.SLIP_START][0]
    assert onset == pytest.approx(0.003, abs=0.0005)


def test_advancing_in_chunks_equals_one_run(case_study: FeederParameters) -> None:
    times = np.arange(0, 1001) / 1000.0
    drive = DriveSchedule(29.6, 40.0, (DriveChange(0.3333, 35.0, 30.0, ramp_s=0.05),))
    whole = FeederSimulator(case_study, (PartSpec(), PartSpec(0.2)), drive).advance(1.0, times)
    sim = FeederSimulator(case_study, (PartSpec(), PartSpec(0.2)), drive)
    chunks = []
    for end in (0.1234, 0.3333, 0.35, 0.7, 1.0):
        chunks.append(sim.advance(end, times[(times >= sim.time_s) & (times <= end)]))
    # a sample at a chunk boundary appears in both chunks
    x = np.concatenate([c.carrier_x_m for c in chunks])
    t = np.concatenate([c.t_s for c in chunks])
    _, first = np.unique(t, return_index=True)
    scale = float(np.max(np.abs(whole.carrier_x_m)))
    np.testing.assert_allclose(x[first], whole.carrier_x_m, rtol=0, atol=1e-12 * scale)
    px = np.concatenate([c.part_x_m for c in chunks])[first]
    np.testing.assert_allclose(px, whole.part_x_m, rtol=0, atol=1e-12)
    events = np.concatenate([c.event_t_s for c in chunks])
    np.testing.assert_allclose(events, whole.event_t_s, rtol=0, atol=1e-12)
