"""The logistic model (Eq. 6 + Eq. 9) against the sharp model, and its part stick-slip events."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

from feeder_ros.physics.drive import DriveChange, DriveSchedule
from feeder_ros.physics.nondimensional import simulate_nondimensional
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import EventKind, PartSpec, Phase, simulate, simulate_carrier
from feeder_ros.physics.smooth_model import (
    SLIP_BACKWARD,
    SLIP_FORWARD,
    STICK,
    SolverOptions,
    integrate_part,
    logistic_stiffness,
    solve_logistic_carrier,
)

DAMPED = FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=30.0, stiffness_model="logistic")
T = np.arange(301) / 1000.0


def test_logistic_stiffness_is_overflow_safe_and_has_the_right_limits() -> None:
    s = np.array([-1.0, -1e-3, 0.0, 1e-3, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        k = logistic_stiffness(s, 3.0, 1.0, 1e6)
    np.testing.assert_array_equal(k, [1.0, 1.0, 2.0, 3.0, 3.0])  # K(0) = (K_f + K_b)/2
    # Eq. 9 as printed: K_b + (K_f - K_b)/(1 + exp(-2*beta*s)) for moderate arguments
    s_small = np.linspace(-2e-6, 2e-6, 9)
    expected = 1.0 + 2.0 / (1.0 + np.exp(-2e6 * s_small))
    np.testing.assert_allclose(logistic_stiffness(s_small, 3.0, 1.0, 1e6), expected, rtol=1e-14)


def test_logistic_converges_to_sharp_as_beta_grows() -> None:
    """Damped, 0.3 s: the error falls like 1/beta^2 with 1/beta against the motion's size."""
    sharp = simulate_carrier(DAMPED.with_changes(stiffness_model="sharp"), 0.3, 1000.0).carrier_x_m
    # the independent non-dimensional solver gives the same sharp solution
    np.testing.assert_allclose(
        simulate_nondimensional(DAMPED, 0.3, 1000.0).x_m, sharp, rtol=0, atol=1e-9 * sharp.max()
    )
    errors = []
    for beta in (1e5, 1e6, 1e7, 1e8):
        carrier = solve_logistic_carrier(DAMPED.with_changes(logistic_beta_per_m=beta), 0.3)
        x, _, _ = carrier.state(T)
        errors.append(float(np.abs(x - sharp).max() / np.abs(sharp).max()))
    assert errors[0] > 1e-3  # beta = 1e5: 1/beta = 10 um against ~1 mm of motion
    for coarse, fine in itertools.pairwise(errors):
        assert fine < coarse / 15.0
    assert errors[-1] < 1e-6


def test_beta_sets_a_length_scale() -> None:
    """x(t; k*A, beta/k) = k*x(t; A, beta): the logistic model is homogeneous only jointly."""
    small = solve_logistic_carrier(DAMPED.with_changes(drive_amplitude_n=0.4), 0.3)
    large = solve_logistic_carrier(DAMPED.with_changes(logistic_beta_per_m=1e4), 0.3)
    x_small, _, _ = small.state(T)
    x_large, _, _ = large.state(T)
    np.testing.assert_allclose(x_large, 100.0 * x_small, rtol=0, atol=1e-7 * np.abs(x_large).max())
    # ... while at the same beta the case-study amplitudes differ in shape, not only in scale
    same_beta = solve_logistic_carrier(DAMPED, 0.3).state(T)[0]
    assert np.abs(same_beta - 100.0 * x_small).max() > 0.05 * np.abs(same_beta).max()


def test_case_study_part_first_slips_at_about_3_ms() -> None:
    params = FeederParameters(drive_amplitude_n=40.0, stiffness_model="logistic")
    carrier = solve_logistic_carrier(params, 0.05)
    grid = carrier.scan_grid()
    _, gv, ga = carrier.state(grid)
    track, transitions = integrate_part(carrier, grid, ga, gv, 0.0, 0.2, 0.1)
    t_first, before, after = transitions[0]
    assert t_first == pytest.approx(0.003, abs=0.0005)
    assert (before, after) == (STICK, SLIP_BACKWARD)  # carrier accelerates forward, part lags
    # at the onset the carrier acceleration is exactly the stick limit
    assert carrier.state(np.array([t_first]))[2][0] == pytest.approx(0.2 * 9.81, rel=1e-9)
    # every slip ends where the relative velocity is zero: the part's velocity is continuous
    t = np.array([t for t, _, _ in transitions])
    cx, cv, _ = carrier.state(t)
    px, pv, _ = track.sample(t, cx, cv)
    px_before, pv_before, _ = track.sample(t - 1e-12, *carrier.state(t - 1e-12)[:2])
    np.testing.assert_allclose(pv, pv_before, atol=1e-8)
    np.testing.assert_allclose(px, px_before, atol=1e-12)
    assert {after for _, _, after in transitions} >= {SLIP_FORWARD, SLIP_BACKWARD}


def test_small_amplitude_part_never_slips() -> None:
    params = FeederParameters(drive_amplitude_n=0.4, stiffness_model="logistic")
    carrier = solve_logistic_carrier(params, 0.5)
    grid = carrier.scan_grid()
    gx, gv, ga = carrier.state(grid)
    assert np.abs(ga).max() < 0.2 * 9.81
    track, transitions = integrate_part(carrier, grid, ga, gv, 0.1, 0.2, 0.1)
    assert transitions == []
    px, _, phase = track.sample(grid, gx, gv)
    np.testing.assert_allclose(px, 0.1 + gx, rtol=0, atol=1e-15)
    assert np.all(phase == STICK)


def test_solver_choice_is_honoured_and_failures_are_loud() -> None:
    params = FeederParameters(drive_amplitude_n=40.0, stiffness_model="logistic")
    capped = solve_logistic_carrier(
        params, 0.1, options=SolverOptions(method="RK45", rtol=1e-3, atol=1e-6, max_step=1e-4)
    )
    assert np.diff(np.concatenate(capped.step_times)).max() <= 1e-4 * (1 + 1e-9)
    loose = solve_logistic_carrier(params, 0.1, options=SolverOptions.ode45_default())
    assert loose.n_steps < capped.n_steps

    def bad_force(t: np.ndarray) -> np.ndarray:
        return np.where(np.asarray(t) > 0.01, np.inf, 0.0)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(RuntimeError, match="solve_ivp failed: "):
            solve_logistic_carrier(params, 0.1, force=bad_force)
    with pytest.raises(ValueError, match="two_way"):
        solve_logistic_carrier(params.with_changes(coupling="two_way"), 0.1)


def test_simulate_dispatches_to_the_logistic_model_and_matches_the_engine() -> None:
    """beta = 1e9 /m at A = 40 N: the logistic model is the sharp one to ~1e-7 of the motion."""
    parts = (PartSpec(), PartSpec(position_m=0.1, static_friction=0.3, kinetic_friction=0.2))
    sharp = FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=30.0)
    exact = simulate(sharp, 0.5, 1000.0, parts=parts)
    smooth = simulate(
        sharp.with_changes(stiffness_model="logistic", logistic_beta_per_m=1e9),
        0.5,
        1000.0,
        parts=parts,
    )
    np.testing.assert_array_equal(smooth.t_s, exact.t_s)
    scale = np.abs(exact.carrier_x_m).max()
    assert np.abs(smooth.carrier_x_m - exact.carrier_x_m).max() < 1e-6 * scale
    np.testing.assert_array_equal(smooth.part_phase, exact.part_phase)
    assert np.abs(smooth.part_x_m - exact.part_x_m).max() < 1e-8
    # the same events, at the same instants
    np.testing.assert_array_equal(smooth.event_kind, exact.event_kind)
    np.testing.assert_array_equal(smooth.event_part, exact.event_part)
    np.testing.assert_allclose(smooth.event_t_s, exact.event_t_s, rtol=0, atol=1e-8)
    np.testing.assert_allclose(smooth.mean_part_speed_mps(), exact.mean_part_speed_mps(), rtol=1e-5)
    np.testing.assert_allclose(smooth.slip_fraction(), exact.slip_fraction(), rtol=1e-6)


def test_logistic_parts_leave_at_the_track_end_like_the_engine() -> None:
    # a part put near the end of a short track while slipping forward at 40 N
    params = FeederParameters(drive_amplitude_n=40.0, track_length_m=0.01)
    parts = (PartSpec(position_m=0.0099),)
    exact = simulate(params, 0.5, 1000.0, parts=parts)
    smooth = simulate(
        params.with_changes(stiffness_model="logistic", logistic_beta_per_m=1e9),
        0.5,
        1000.0,
        parts=parts,
    )
    assert np.isfinite(exact.part_exit_t_s[0])
    assert smooth.part_exit_t_s[0] == pytest.approx(exact.part_exit_t_s[0], abs=1e-7)
    after = smooth.t_s > smooth.part_exit_t_s[0]
    assert np.all(np.isnan(smooth.part_x_m[after, 0]))
    assert np.all(smooth.part_phase[after, 0] == Phase.EXITED)
    assert smooth.part_end_x_m[0] == pytest.approx(exact.part_end_x_m[0], abs=1e-9)


def test_drive_changes_are_followed_like_the_engine() -> None:
    """A step and a ramp in the drive: integrated piecewise, with the same DRIVE_CHANGE events."""
    params = FeederParameters(drive_amplitude_n=10.0, damping_ns_per_m=30.0)
    drive = (
        DriveSchedule(29.6, 10.0)
        .with_change(DriveChange(0.1, 35.0, 40.0))
        .with_change(DriveChange(0.2, 25.0, 20.0, ramp_s=0.05))
    )
    exact = simulate(params, 0.4, 1000.0, parts=(PartSpec(),), drive=drive)
    smooth = simulate(
        params.with_changes(stiffness_model="logistic", logistic_beta_per_m=1e9),
        0.4,
        1000.0,
        parts=(PartSpec(),),
        drive=drive,
    )
    scale = np.abs(exact.carrier_x_m).max()
    assert np.abs(smooth.carrier_x_m - exact.carrier_x_m).max() < 1e-6 * scale
    changes = smooth.event_t_s[smooth.event_kind == EventKind.DRIVE_CHANGE]
    np.testing.assert_array_equal(
        changes, exact.event_t_s[exact.event_kind == EventKind.DRIVE_CHANGE]
    )
    np.testing.assert_allclose(changes, [0.1, 0.2])
    np.testing.assert_array_equal(smooth.part_phase, exact.part_phase)
