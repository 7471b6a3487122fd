"""Drift-free carrier velocity from acceleration: harmonic fit, period order, frequency estimate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from feeder_ros.estimation.carrier_velocity import (
    CarrierFitError,
    estimate_frequency,
    fit_harmonics,
    refine_frequency,
    select_period_order,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import simulate

RATE = 1000.0
NOISE_SIGMA = 300e-6 * 9.80665 * math.sqrt(RATE / 2.0)  # 300 ug/sqrt(Hz) at 1 kHz
BIAS = 0.05


def _damped(frequency_hz: float, amplitude_n: float = 20.0) -> FeederParameters:
    return FeederParameters(
        damping_ns_per_m=50.0,
        drive_frequency_hz=frequency_hz,
        drive_amplitude_n=amplitude_n,
        track_length_m=1e3,
    )


def test_fit_integrates_a_harmonic_signal_exactly_and_absorbs_the_bias() -> None:
    w = 2.0 * math.pi * 12.5
    t = np.arange(800) / RATE + 3.0
    amps = {1: 2.0 + 1.0j, 3: -0.5j, 7: 0.25}
    accel = 0.3 + sum((c * np.exp(1j * k * w * t)).real for k, c in amps.items())
    v_true = sum((c / (1j * k * w) * np.exp(1j * k * w * t)).real for k, c in amps.items())
    x_true = sum((-c / (k * w) ** 2 * np.exp(1j * k * w * t)).real for k, c in amps.items())
    fit = fit_harmonics(t, accel, 12.5, 10, t_ref_s=0.0)
    x, v, a = fit.evaluate(t)
    assert fit.offset_mps2 == pytest.approx(0.3, abs=1e-10)
    np.testing.assert_allclose(a, accel - 0.3, atol=1e-10)
    np.testing.assert_allclose(v, v_true, atol=1e-12)
    np.testing.assert_allclose(x, x_true, atol=1e-14)
    assert fit.residual_rms_mps2 < 1e-10
    # irregular sampling with a hole: still exact (least squares, not a DFT)
    keep = np.ones(t.size, bool)
    keep[200:260] = False
    keep[::7] = False
    fit2 = fit_harmonics(t[keep], accel[keep], 12.5, 10)
    np.testing.assert_allclose(fit2.velocity(t), v_true, atol=1e-11)


def test_fit_refuses_too_few_samples() -> None:
    with pytest.raises(CarrierFitError, match="cannot fit"):
        fit_harmonics(np.arange(10) / RATE, np.zeros(10), 10.0, 20)


def test_residual_splits_into_white_noise_and_smooth_model_error() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(2000) / RATE
    periodic = np.sin(2 * math.pi * 20.0 * t)
    noisy = periodic + rng.normal(0.0, 0.1, t.size)
    fit = fit_harmonics(t, noisy, 20.0, 10)
    assert fit.noise_rms_mps2 == pytest.approx(0.1, rel=0.05)
    assert fit.model_error_rms_mps2 < 0.03
    # a component at a frequency the model does not have is a smooth model error
    wrong = periodic + 0.5 * np.sin(2 * math.pi * 7.3 * t)
    fit = fit_harmonics(t, wrong, 20.0, 10)
    assert fit.model_error_rms_mps2 == pytest.approx(0.5 / math.sqrt(2.0), rel=0.1)
    assert fit.noise_rms_mps2 < 0.05


@pytest.mark.parametrize(("frequency_hz", "order"), [(25.0, 2), (33.0, 3), (22.0, 2)])
def test_damped_carrier_velocity_from_noisy_acceleration(frequency_hz: float, order: int) -> None:
    """Steady state of the damped carrier: subharmonic period found, velocity within 1 % rms."""
    sim = simulate(_damped(frequency_hz), 12.0, RATE, parts=())
    rng = np.random.default_rng(7)
    accel = sim.carrier_a_mps2 + rng.normal(0.0, NOISE_SIGMA, sim.t_s.size) + BIAS
    sel = (sim.t_s >= 10.0) & (sim.t_s < 11.0)
    n, fit = select_period_order(sim.t_s[sel], accel[sel], frequency_hz, 6, 450.0)
    assert n == order
    assert fit.offset_mps2 == pytest.approx(BIAS, abs=0.01)
    assert fit.model_error_rms_mps2 < 0.05
    v_true = sim.carrier_v_mps[sel]
    err = fit.velocity(sim.t_s[sel]) - v_true
    assert np.sqrt(np.mean(err**2)) < 0.01 * np.sqrt(np.mean(v_true**2))
    # the model extrapolates one second ahead (periodic steady state): still within 1 %
    ahead = sim.t_s >= 11.0
    err = fit.velocity(sim.t_s[ahead]) - sim.carrier_v_mps[ahead]
    assert np.sqrt(np.mean(err**2)) < 0.01 * np.sqrt(np.mean(v_true**2))


def test_no_drift_over_a_long_run_unlike_plain_integration() -> None:
    """60 s: windowed fits stay as accurate at the end as at the start; integrating drifts."""
    sim = simulate(_damped(25.0), 60.0, RATE, parts=())
    rng = np.random.default_rng(3)
    accel = sim.carrier_a_mps2 + rng.normal(0.0, NOISE_SIGMA, sim.t_s.size) + BIAS
    v_rms = float(np.sqrt(np.mean(sim.carrier_v_mps[-5000:] ** 2)))
    errors = []
    for start in (5.0, 30.0, 58.0):
        sel = (sim.t_s >= start) & (sim.t_s < start + 1.0)
        _, fit = select_period_order(sim.t_s[sel], accel[sel], 25.0, 6, 450.0)
        err = fit.velocity(sim.t_s[sel]) - sim.carrier_v_mps[sel]
        errors.append(float(np.sqrt(np.mean(err**2))))
        assert abs(float(np.mean(err))) < 1e-3 * v_rms  # no offset
    assert max(errors) < 0.01 * v_rms
    naive = np.concatenate(([0.0], np.cumsum(0.5 * (accel[1:] + accel[:-1]) / RATE)))
    assert abs(naive[-1] - sim.carrier_v_mps[-1]) > 100.0 * v_rms  # the bias alone: 3 m/s


def test_chaotic_undamped_carrier_is_flagged_by_the_model_error() -> None:
    params = FeederParameters(drive_amplitude_n=40.0, track_length_m=1e3)  # c = 0: chaotic
    sim = simulate(params, 12.0, RATE, parts=())
    sel = sim.t_s >= 11.0
    _, fit = select_period_order(sim.t_s[sel], sim.carrier_a_mps2[sel], 29.6, 6, 450.0)
    assert fit.model_error_rms_mps2 > 0.5  # m/s^2, against a stick limit of 1.96


def test_frequency_estimate_and_refinement() -> None:
    sim = simulate(_damped(33.0), 8.0, RATE, parts=())
    rng = np.random.default_rng(5)
    accel = sim.carrier_a_mps2 + rng.normal(0.0, NOISE_SIGMA, sim.t_s.size) + BIAS
    sel = sim.t_s >= 7.0
    coarse = estimate_frequency(sim.t_s[sel], accel[sel], 2.0, 300.0)
    assert coarse == pytest.approx(33.0, rel=2e-3)  # the strongest line is the drive here
    fine = refine_frequency(sim.t_s[sel], accel[sel], coarse, 3, 450.0, 0.01)
    assert fine == pytest.approx(33.0, rel=2e-5)
