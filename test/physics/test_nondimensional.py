"""Eqs. 19-20 and the Fig. 6 algorithm in non-dimensional form against the dimensional solutions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from feeder_ros.physics.nondimensional import (
    BACKWARD,
    FORWARD,
    NondimensionalScales,
    simulate_nondimensional,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import EventKind, simulate_carrier

CASE = FeederParameters(drive_amplitude_n=40.0)


def test_ratios_are_derived_from_eq_20() -> None:
    scales = NondimensionalScales.from_parameters(CASE)
    # mu = v_cf/v_cb = K_b/K_f = (L_f/L_b)^3 and eta = omega_f/omega_b = (L_b/L_f)^(3/2)
    assert scales.mu == pytest.approx((0.05 / 0.15) ** 3, rel=1e-12)
    assert scales.eta == pytest.approx((0.15 / 0.05) ** 1.5, rel=1e-12)
    assert scales.eta == pytest.approx(
        CASE.forward_natural_frequency_hz / CASE.backward_natural_frequency_hz, rel=1e-12
    )
    # t_cD = 1/omega_D and omega_D = t_cD*omega_d
    omega_f = 2 * math.pi * CASE.forward_natural_frequency_hz
    assert scales.forward.time_s == pytest.approx(1 / omega_f, rel=1e-12)
    assert scales.forward.frequency == pytest.approx(29.6 / 32.93, rel=1e-3)
    assert scales.forward.displacement_m == pytest.approx(
        40.0 / (CASE.forward_stiffness_n_per_m * CASE.cos_theta), rel=1e-12
    )
    # Eq. 11 in branch units: mu_s*g*t_c^2/v_c, i.e. the threshold over the unit acceleration
    assert scales.backward.stick_limit * scales.backward.acceleration_mps2 == pytest.approx(
        0.2 * 9.81, rel=1e-12
    )


def test_state_mapping_preserves_the_dimensional_state() -> None:
    scales = NondimensionalScales.from_parameters(CASE)
    f, b = scales.forward, scales.backward
    tau_b, chi_b, dchi_b = scales.map_state(FORWARD, 3.0, 0.7, -1.3)
    assert tau_b * b.time_s == pytest.approx(3.0 * f.time_s, rel=1e-14)
    assert chi_b * b.displacement_m == pytest.approx(0.7 * f.displacement_m, rel=1e-14)
    assert dchi_b * b.velocity_mps == pytest.approx(-1.3 * f.velocity_mps, rel=1e-14)
    assert scales.map_state(BACKWARD, tau_b, chi_b, dchi_b) == pytest.approx((3.0, 0.7, -1.3))


def _dimensional_reference(params: FeederParameters, duration: float, t: np.ndarray) -> np.ndarray:
    """Eq. 6 + Eq. 7 with DOP853 at tight tolerance, restarted at each displacement switch."""
    mass = params.equivalent_mass_kg
    stiffness = {
        FORWARD: params.forward_stiffness_n_per_m * params.cos_theta,
        BACKWARD: params.backward_stiffness_n_per_m * params.cos_theta,
    }
    omega = 2 * math.pi * params.drive_frequency_hz
    amp, c = params.drive_amplitude_n, params.damping_ns_per_m
    x = np.zeros_like(t)
    start, y, branch = 0.0, [0.0, 0.0], FORWARD
    while start < duration:
        k = stiffness[branch]

        def crossing(_t: float, y: np.ndarray) -> float:
            return float(y[0])

        crossing.terminal = True  # type: ignore[attr-defined]
        crossing.direction = -branch  # type: ignore[attr-defined]
        sol = solve_ivp(
            lambda tt, y, k=k: [y[1], (amp * np.sin(omega * tt) - c * y[1] - k * y[0]) / mass],
            (start, duration),
            y,
            method="DOP853",
            rtol=1e-12,
            atol=1e-17,
            events=crossing,
            dense_output=True,
        )
        inside = (t >= start) & (t <= sol.t[-1])
        x[inside] = sol.sol(t[inside])[0]
        start, y, branch = float(sol.t[-1]), [0.0, float(sol.y[1, -1])], -branch
    return x


@pytest.mark.parametrize(("amplitude", "damping"), [(40.0, 0.0), (0.4, 0.0), (40.0, 30.0)])
def test_nondimensional_solution_matches_dimensional_reference(
    amplitude: float, damping: float
) -> None:
    params = CASE.with_changes(drive_amplitude_n=amplitude, damping_ns_per_m=damping)
    result = simulate_nondimensional(params, 1.0, 1000.0)
    assert result.t_s[1] == 0.001
    assert result.t_s[-1] == 1.0
    reference = _dimensional_reference(params, 1.0, result.t_s)
    scale = np.abs(reference).max()
    assert np.abs(result.x_m - reference).max() <= 1e-8 * scale
    # the forward branch holds exactly where the displacement is positive
    assert np.all(result.branch[result.x_m > 1e-9 * scale] == FORWARD)
    assert np.all(result.branch[result.x_m < -1e-9 * scale] == BACKWARD)
    # every switch found is a sign change of the reference's displacement, and vice versa
    changes = np.count_nonzero(np.diff(np.sign(reference[1:])) != 0)
    assert result.switch_t_s.size >= 10
    assert abs(result.switch_t_s.size - changes) <= 1


def test_amplitude_homogeneity_in_nondimensional_units() -> None:
    """chi does not depend on A: v(t; k*A) = k*v(t; A) (MODEL-NOTES)."""
    small = simulate_nondimensional(CASE.with_changes(drive_amplitude_n=0.4), 0.5, 1000.0)
    large = simulate_nondimensional(CASE, 0.5, 1000.0)
    np.testing.assert_allclose(small.chi, large.chi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(large.x_m, 100.0 * small.x_m, rtol=0, atol=1e-9 * large.x_m.max())


def test_refusals() -> None:
    with pytest.raises(ValueError, match="A > 0"):
        NondimensionalScales.from_parameters(CASE.with_changes(drive_amplitude_n=0.0))
    with pytest.raises(ValueError, match="duration_s"):
        simulate_nondimensional(CASE, -1.0, 1000.0)


@pytest.mark.parametrize("amplitude", [0.4, 40.0])
def test_nondimensional_solution_matches_the_event_driven_engine(amplitude: float) -> None:
    """Undamped, one-way, 2 s (well inside the predictable horizon of the chaotic undamped case)."""
    params = CASE.with_changes(drive_amplitude_n=amplitude)
    nondim = simulate_nondimensional(params, 2.0, 1000.0)
    engine = simulate_carrier(params, 2.0, 1000.0)
    np.testing.assert_array_equal(nondim.t_s, engine.t_s)
    for ours, theirs in (
        (nondim.x_m, engine.carrier_x_m),
        (nondim.v_mps, engine.carrier_v_mps),
        (nondim.a_mps2, engine.carrier_a_mps2),
    ):
        assert np.abs(ours - theirs).max() <= 1e-9 * np.abs(theirs).max()
    switches = engine.event_t_s[engine.event_kind == EventKind.BRANCH_SWITCH]
    np.testing.assert_allclose(nondim.switch_t_s, switches, rtol=0, atol=1e-12)


@pytest.mark.parametrize(("amplitude", "damping"), [(40.0, 0.0), (0.4, 0.0), (10.0, 10.0)])
def test_velocity_switching_with_filippov_holds_matches_the_engine(
    amplitude: float, damping: float
) -> None:
    """Fig. 6 as printed switches on the velocity; both solvers hold the carrier at v' = 0 while
    the drive lies between the two spring forces (branch code 0)."""
    params = CASE.with_changes(
        drive_amplitude_n=amplitude, damping_ns_per_m=damping, stiffness_switch="velocity"
    )
    nondim = simulate_nondimensional(params, 1.0, 1000.0)
    engine = simulate_carrier(params, 1.0, 1000.0)
    held = engine.branch == 0
    assert held.any()  # the sliding mode does occur in the case study
    np.testing.assert_array_equal(nondim.branch, engine.branch)
    scale = np.abs(engine.carrier_x_m).max()
    assert np.abs(nondim.x_m - engine.carrier_x_m).max() <= 1e-9 * scale
    assert np.all(nondim.v_mps[held] == 0.0)
    switch_kinds = (
        EventKind.BRANCH_SWITCH,
        EventKind.SLIDING_START,
        EventKind.SLIDING_END,
    )
    engine_switches = engine.event_t_s[np.isin(engine.event_kind, switch_kinds)]
    np.testing.assert_allclose(nondim.switch_t_s, engine_switches, rtol=0, atol=1e-10)
