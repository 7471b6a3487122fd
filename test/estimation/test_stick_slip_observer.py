"""Stick-slip observer: on the true carrier motion it reproduces the exact simulator's part."""

from __future__ import annotations

import math

import numpy as np
import pytest

from feeder_ros.estimation.stick_slip_observer import (
    PHASE_SLIP_BACKWARD,
    PHASE_SLIP_FORWARD,
    PHASE_STICK,
    PartModel,
    StickSlipObserver,
)
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.simulation import Phase, simulate


def test_phase_codes_match_the_simulator_and_the_message() -> None:
    assert (PHASE_STICK, PHASE_SLIP_FORWARD, PHASE_SLIP_BACKWARD) == (
        Phase.STICK,
        Phase.SLIP_FORWARD,
        Phase.SLIP_BACKWARD,
    )


def test_part_model_from_parameters_and_validation() -> None:
    params = FeederParameters(groove_angle_deg=90.0)
    part = PartModel.from_parameters(params)
    assert part.stick_limit_mps2 == pytest.approx(params.stick_limit_mps2)
    assert part.slip_deceleration_mps2 == pytest.approx(params.slip_deceleration_mps2)
    with pytest.raises(ParameterError, match="must not exceed"):
        PartModel(static_friction=0.1, kinetic_friction=0.2)
    with pytest.raises(ParameterError, match="> 0"):
        PartModel(gravity_mps2=-9.81)


@pytest.mark.parametrize(
    ("damping", "frequency_hz", "amplitude_n"),
    [
        (50.0, 25.0, 20.0),
        (50.0, 33.0, 20.0),
        (50.0, 22.0, 10.0),
        (20.0, 31.0, 40.0),
        (0.0, 29.6, 40.0),
    ],
)
def test_observer_on_true_carrier_reproduces_the_simulator(
    damping: float, frequency_hz: float, amplitude_n: float
) -> None:
    params = FeederParameters(
        damping_ns_per_m=damping,
        drive_frequency_hz=frequency_hz,
        drive_amplitude_n=amplitude_n,
        track_length_m=1e3,
    )
    sim = simulate(params, 10.0, 1000.0)
    obs = StickSlipObserver(PartModel.from_parameters(params))
    out = obs.update(sim.t_s, sim.carrier_v_mps, sim.carrier_a_mps2)
    phase = sim.part_phase[:, 0]
    assert np.mean(out.phase == phase) >= 0.9999
    assert {1, 2} <= set(np.unique(phase).tolist())  # slips both ways: not a trivial case
    v_scale = float(np.max(np.abs(sim.carrier_v_mps)))
    np.testing.assert_allclose(out.part_v_mps, sim.part_v_mps[:, 0], atol=1e-3 * v_scale)
    span = sim.t_s[-1] - sim.t_s[0]
    # mean speed to 0.02 % of itself (the cubic interpolation between 1 kHz samples is the only
    # approximation), slip fraction to 1e-5
    assert np.sum(out.part_dx_m) / span == pytest.approx(sim.mean_part_speed_mps()[0], rel=2e-4)
    assert np.sum(out.slip_s) / span == pytest.approx(sim.slip_fraction()[0], abs=1e-5)


def test_chunked_updates_equal_one_update() -> None:
    params = FeederParameters(
        damping_ns_per_m=50.0, drive_amplitude_n=20.0, drive_frequency_hz=25.0
    )
    sim = simulate(params, 2.0, 1000.0)
    part = PartModel.from_parameters(params)
    whole = StickSlipObserver(part).update(sim.t_s, sim.carrier_v_mps, sim.carrier_a_mps2)
    obs = StickSlipObserver(part)
    pieces = [
        obs.update(
            sim.t_s[i : i + 37], sim.carrier_v_mps[i : i + 37], sim.carrier_a_mps2[i : i + 37]
        )
        for i in range(0, sim.t_s.size, 37)
    ]
    np.testing.assert_array_equal(np.concatenate([p.phase for p in pieces]), whole.phase)
    np.testing.assert_array_equal(np.concatenate([p.part_v_mps for p in pieces]), whole.part_v_mps)


def test_constant_acceleration_above_the_limit_slips_backward_analytically() -> None:
    """a = 3 m/s^2 > L = 1.962: the part lags from t = 0 with u = D*t (closed form)."""
    part = PartModel()
    t = np.linspace(0.0, 0.1, 11)
    out = StickSlipObserver(part).update(t, 3.0 * t, np.full(t.size, 3.0))
    assert np.all(out.phase == PHASE_SLIP_BACKWARD)
    np.testing.assert_allclose(out.part_v_mps, part.slip_deceleration_mps2 * t, atol=1e-15)
    D = part.slip_deceleration_mps2
    assert np.sum(out.part_dx_m) == pytest.approx(0.5 * D * 0.1**2, rel=1e-12)
    assert np.sum(out.slip_s) == pytest.approx(0.1, rel=1e-12)


def test_slip_onset_and_restick_are_located_inside_the_interval() -> None:
    """v = V sin(w t): slip starts where |a| = L, found between coarse samples (50 per period)."""
    part = PartModel()
    L = part.stick_limit_mps2
    w = 2.0 * math.pi * 20.0
    V = 2.0 * L / w  # peak acceleration 2L
    t = np.arange(0, 51) / 1000.0
    out = StickSlipObserver(part).update(t, V * np.sin(w * t), V * w * np.cos(w * t))
    # a(0) = 2L > L: slipping backward from the start; the part re-sticks when u = v
    assert out.phase[0] == PHASE_SLIP_BACKWARD
    # dense reference: the same observer on a 100x finer sampling of the same motion
    tf = np.arange(0, 5001) / 100000.0
    ref = StickSlipObserver(part).update(tf, V * np.sin(w * tf), V * w * np.cos(w * tf))
    np.testing.assert_array_equal(out.phase, ref.phase[::100])
    np.testing.assert_allclose(out.part_v_mps, ref.part_v_mps[::100], atol=1e-6)
    assert np.sum(out.slip_s) == pytest.approx(np.sum(ref.slip_s), abs=2e-6)


def test_update_rejects_times_that_go_back() -> None:
    obs = StickSlipObserver(PartModel())
    obs.update([0.0, 0.001], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(ValueError, match="not after"):
        obs.update([0.001], [0.0], [0.0])
    with pytest.raises(ValueError, match="strictly increasing"):
        obs.update([0.003, 0.002], [0.0, 0.0], [0.0, 0.0])
