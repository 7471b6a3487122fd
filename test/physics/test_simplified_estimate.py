"""The paper's simplified estimate (Eqs. 17/18) and set S against the full hybrid simulation."""

from __future__ import annotations

import re

import numpy as np
import pytest

from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simplified_estimate import (
    SimplifiedEstimate,
    carrier_velocity_roots,
    simplified_estimate,
    stick_slip_conditions,
)
from feeder_ros.physics.simulation import (
    EventKind,
    FeederSimulator,
    PartSpec,
    Phase,
    SimulationResult,
    simulate,
)

DURATION = 5.0


def test_velocity_roots_on_an_analytic_sine() -> None:
    t = np.linspace(0.0, 2.0, 201)
    w = 2 * np.pi
    roots, x_roots = carrier_velocity_roots(
        t, np.sin(w * t), w * np.cos(w * t), -w * w * np.sin(w * t)
    )
    np.testing.assert_allclose(roots, [0.25, 0.75, 1.25, 1.75], rtol=0, atol=1e-8)
    np.testing.assert_allclose(x_roots, [1.0, -1.0, 1.0, -1.0], rtol=0, atol=1e-8)


def _run(params: FeederParameters) -> tuple[SimulationResult, SimplifiedEstimate, SimulationResult]:
    """Full model at 1 kHz, the estimate from its carrier samples, and the part at the cuts."""
    result = simulate(params, DURATION, 1000.0, parts=(PartSpec(),))
    estimate = simplified_estimate(
        params, result.t_s, result.carrier_x_m, result.carrier_v_mps, result.carrier_a_mps2
    )
    cuts = np.unique(np.concatenate([estimate.start_t_s, estimate.end_t_s]))
    at_cuts = FeederSimulator(params, (PartSpec(),)).advance(DURATION, cuts)
    return result, estimate, at_cuts


def _per_interval(
    result: SimulationResult, estimate: SimplifiedEstimate, at_cuts: SimulationResult
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    index = {t: i for i, t in enumerate(at_cuts.t_s)}
    first = np.array([index[t] for t in estimate.start_t_s])
    last = np.array([index[t] for t in estimate.end_t_s])
    travel = at_cuts.part_x_m[last, 0] - at_cuts.part_x_m[first, 0]
    part_events = result.event_t_s[result.event_part == 0]
    quiet = np.array(
        [
            not np.any((part_events > a) & (part_events < b))
            for a, b in zip(estimate.start_t_s, estimate.end_t_s, strict=True)
        ]
    )
    return travel, quiet, at_cuts.part_phase[first, 0], at_cuts.part_v_mps[first, 0]


@pytest.mark.parametrize(
    "params",
    [
        FeederParameters(drive_amplitude_n=0.4),
        FeederParameters(drive_amplitude_n=10.0, damping_ns_per_m=30.0),
        FeederParameters(drive_amplitude_n=20.0, damping_ns_per_m=30.0),
    ],
)
def test_pure_drag_matches_the_full_model_on_forward_strokes_without_slip(
    params: FeederParameters,
) -> None:
    result, estimate, at_cuts = _run(params)
    travel, quiet, phase0, _ = _per_interval(result, estimate, at_cuts)
    drag = estimate.forward & quiet & (phase0 == Phase.STICK)
    assert drag.sum() >= 20
    np.testing.assert_allclose(travel[drag], estimate.displacement_m[drag], rtol=0, atol=2e-9)


@pytest.mark.parametrize("damping", [0.0, 30.0])
def test_pure_slip_kinematics_match_on_backward_strokes_spent_slipping(damping: float) -> None:
    """Where the part slips forward over a whole backward stroke, the full model moves it by
    ``u0*dt - mu_d*g*dt^2/2``: the estimate's term, except that the estimate takes ``u0`` to be the
    carrier's velocity at the root (zero) instead of the part's."""
    params = FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=damping)
    result, estimate, at_cuts = _run(params)
    travel, quiet, phase0, u0 = _per_interval(result, estimate, at_cuts)
    slip = ~estimate.forward & quiet & (phase0 == Phase.SLIP_FORWARD)
    assert slip.sum() >= 10
    dt = estimate.end_t_s - estimate.start_t_s
    np.testing.assert_allclose(
        travel[slip], estimate.displacement_m[slip] + u0[slip] * dt[slip], rtol=0, atol=1e-12
    )
    assert np.all(np.abs(u0[slip] * dt[slip]) > 1e-7)  # ... and that difference is not small


def test_where_and_how_much_the_estimate_differs() -> None:
    """Documented in docs/model.md: the estimate ignores Eq. 11."""
    # A = 0.4 N: the part never slips and follows the carrier; the estimate charges every backward
    # stroke a slip of mu_d*g*dt^2/2 and predicts about -6 mm/s.
    result, estimate, _ = _run(FeederParameters(drive_amplitude_n=0.4))
    full = float(result.mean_part_speed_mps()[0])
    assert float(result.slip_fraction()[0]) == 0.0
    assert abs(full) < 2e-6
    assert estimate.mean_speed_mps == pytest.approx(-6.0e-3, rel=0.05)
    # A = 40 N, damped (periodic): the full model moves the part back at about 2 mm/s, the
    # estimate forward at about 5 mm/s: even the direction is wrong.
    result, estimate, _ = _run(FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=30.0))
    full = float(result.mean_part_speed_mps()[0])
    assert full == pytest.approx(-1.8e-3, rel=0.1)
    assert estimate.mean_speed_mps == pytest.approx(5.1e-3, rel=0.1)
    assert estimate.drag_m > 0.0 > estimate.slip_m


def test_set_s_margins() -> None:
    small = FeederParameters(drive_amplitude_n=0.4)
    result = simulate(small, 1.0, 1000.0)
    conditions = stick_slip_conditions(small, result.carrier_v_mps, result.carrier_a_mps2)
    forward = result.carrier_v_mps > 0
    assert conditions.stick_limit_mps2 == pytest.approx(0.2 * 9.81)
    assert conditions.forward_peak_mps2 == np.abs(result.carrier_a_mps2[forward]).max()
    assert conditions.backward_peak_mps2 == np.abs(result.carrier_a_mps2[~forward]).max()
    # 0.4 N: forward drag holds, but backward strokes never reach the threshold: S fails, no slip
    assert conditions.forward_margin_mps2 > 1.0
    assert conditions.backward_margin_mps2 < -1.0
    assert not conditions.holds
    # 40 N: the forward condition fails, and the full model indeed slips in forward strokes
    large = FeederParameters(drive_amplitude_n=40.0)
    result = simulate(large, 1.0, 1000.0, parts=(PartSpec(),))
    conditions = stick_slip_conditions(large, result.carrier_v_mps, result.carrier_a_mps2)
    assert conditions.forward_margin_mps2 < 0.0 < conditions.backward_margin_mps2
    assert not conditions.holds
    onsets = result.event_t_s[result.event_kind == EventKind.SLIP_START]
    v_at_onsets = np.interp(onsets, result.t_s, result.carrier_v_mps)
    assert np.any(v_at_onsets > 0.0)
    # a custom threshold turns S on
    assert (
        stick_slip_conditions(
            large, result.carrier_v_mps, result.carrier_a_mps2, static_friction=10.0
        ).forward_margin_mps2
        > 0.0
    )


def _sine_carrier(n: int = 101) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 1.0, n)
    w = 2 * np.pi * 3.0
    return t, 1e-3 * np.sin(w * t), 1e-3 * w * np.cos(w * t), -1e-3 * w * w * np.sin(w * t)


@pytest.mark.parametrize("name", ["t", "x", "v", "a"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_samples_are_refused_by_name(name: str, bad: float) -> None:
    """A NaN sample would turn the roots and the travel into noise without a word."""
    arrays = dict(zip("txva", _sine_carrier(), strict=True))
    arrays[name][7] = bad
    arrays[name][9] = bad
    message = rf"^{name}\[7\]={bad!r} is not finite \(2 such sample\(s\)\)$"
    with pytest.raises(ValueError, match=message):
        simplified_estimate(FeederParameters(), arrays["t"], arrays["x"], arrays["v"], arrays["a"])
    with pytest.raises(ValueError, match=message):
        carrier_velocity_roots(arrays["t"], arrays["x"], arrays["v"], arrays["a"])
    if name in "va":
        with pytest.raises(ValueError, match=message):
            stick_slip_conditions(FeederParameters(), arrays["v"], arrays["a"])


def test_sample_times_out_of_order_or_shapes_that_differ_are_refused() -> None:
    t, x, v, a = _sine_carrier()
    t[40] = t[39]
    expected = f"strictly ascending: t[40]={float(t[39])!r} after t[39]={float(t[39])!r}"
    with pytest.raises(ValueError, match=re.escape(expected) + "$"):
        simplified_estimate(FeederParameters(), t, x, v, a)
    t, x, v, a = _sine_carrier()
    with pytest.raises(ValueError, match=r"1-D of one length, got t \(101,\), x \(100,\)"):
        carrier_velocity_roots(t, x[:-1], v, a)
    with pytest.raises(ValueError, match=r"got v \(101,\), a \(1, 101\)$"):
        stick_slip_conditions(FeederParameters(), v, a[None, :])
    with pytest.raises(ValueError, match="at least 2 samples are needed, got 1"):
        simplified_estimate(FeederParameters(), t[:1], x[:1], v[:1], a[:1])


@pytest.mark.parametrize("friction", [np.nan, -0.1, np.inf])
def test_friction_overrides_are_checked(friction: float) -> None:
    t, x, v, a = _sine_carrier()
    with pytest.raises(ValueError, match=rf"^kinetic_friction={friction!r} "):
        simplified_estimate(FeederParameters(), t, x, v, a, kinetic_friction=friction)
    with pytest.raises(ValueError, match=rf"^static_friction={friction!r} "):
        stick_slip_conditions(FeederParameters(), v, a, static_friction=friction)
    # the same call with a valid override works, and the override is used
    low = stick_slip_conditions(FeederParameters(), v, a, static_friction=0.1)
    high = stick_slip_conditions(FeederParameters(), v, a, static_friction=0.2)
    assert high.stick_limit_mps2 == pytest.approx(2.0 * low.stick_limit_mps2, rel=1e-15)
