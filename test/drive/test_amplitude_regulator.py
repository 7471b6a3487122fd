"""The amplitude regulator: the line fit on synthetic signals, the control law's rules, and the
closed loop around the exact carrier physics through a live stiffness drop."""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pytest

from feeder_ros.drive.amplitude_regulator import (
    AmplitudeError,
    AmplitudeMeasurement,
    AmplitudeRegulator,
    AmplitudeSettings,
    LineAmplitude,
    RegulatorOutput,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import FeederSimulator
from feeder_ros.sensors.accelerometer import AccelerometerModel

RATE_HZ = 1000.0  # the IMU's sample rate


def _signal(t: np.ndarray, f: float, amplitude: float, phase: float = 0.4) -> np.ndarray:
    """An offset, the line, a 2nd and a 3rd harmonic (rms sqrt((2**2 + 1**2) / 2))."""
    w = 2.0 * math.pi * f * t
    return 3.0 + amplitude * np.sin(w + phase) + 2.0 * np.sin(2.0 * w) + np.cos(3.0 * w + 1.0)


def _feed(
    line: LineAmplitude, t: np.ndarray, a: np.ndarray, f: float, batch: int = 37
) -> list[AmplitudeMeasurement]:
    out: list[AmplitudeMeasurement] = []
    for i in range(0, t.size, batch):
        out += line.add(t[i : i + batch], a[i : i + batch], f)
    return out


# -- settings -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"window_periods": 1}, "window_periods=1"),
        ({"window_periods": 2.5}, "window_periods=2.5"),
        ({"gain": 0.0}, "gain=0.0"),
        ({"gain": 1.5}, "gain=1.5"),
        ({"gain": math.nan}, "gain=nan"),
        ({"max_step_percent": -1.0}, "max_step_percent=-1.0"),
        ({"stale_after_s": math.inf}, "stale_after_s=inf"),
    ],
)
def test_settings_refuse_what_cannot_work_naming_the_value(
    changes: dict[str, float], named: str
) -> None:
    with pytest.raises(AmplitudeError, match=re.escape(named)):
        AmplitudeSettings(**changes)  # type: ignore[arg-type]


def test_the_regulator_needs_a_positive_limit_and_finite_inputs() -> None:
    with pytest.raises(AmplitudeError, match=r"max_amplitude_percent=0\.0"):
        AmplitudeRegulator(AmplitudeSettings(), 0.0)
    reg = AmplitudeRegulator(AmplitudeSettings(), 100.0)
    with pytest.raises(AmplitudeError, match="applied_percent=nan"):
        reg.update(AmplitudeMeasurement(1.0, 30.0, 1.0, 0.0), math.nan)
    with pytest.raises(AmplitudeError, match="frequency_hz=0"):
        LineAmplitude(AmplitudeSettings()).add([0.0], [1.0], 0.0)


# -- the line -------------------------------------------------------------------------------
def test_the_line_is_exact_despite_offset_harmonics_and_noise() -> None:
    f = 30.0
    t = np.arange(1, 2001) / RATE_HZ  # 2 s: 7 whole windows of 8 periods (0.2667 s)
    rng = np.random.default_rng(3)
    noise = 0.05
    a = _signal(t, f, 12.0) + rng.normal(0.0, noise, t.size)
    line = LineAmplitude(AmplitudeSettings(window_periods=8))
    got = _feed(line, t, a, f)
    assert [m.t_s for m in got] == pytest.approx(0.001 + np.arange(1, 8) * 8 / f)
    for m in got:
        assert m.frequency_hz == f
        # noise alone moves the amplitude by about noise * sqrt(2 / 267) = 0.004
        assert m.amplitude_mps2 == pytest.approx(12.0, abs=0.02)
        assert m.residual_mps2 == pytest.approx(math.sqrt(2.5 + noise**2), rel=0.02)
    clean = LineAmplitude(AmplitudeSettings(window_periods=8))
    for m in _feed(clean, t, _signal(t, f, 12.0), f):  # harmonics are fitted: no leakage at all
        assert m.amplitude_mps2 == pytest.approx(12.0, rel=1e-9)


def test_the_lines_of_a_period_3_orbit_do_not_leak_into_the_line() -> None:
    """The carrier at 30 Hz runs an orbit of 3 drive periods (lines at 10 and 20 Hz): the default
    window of 6 periods holds whole orbits; 8 periods would not."""
    f = 30.0
    t = np.arange(1, 1601) / RATE_HZ
    w = 2.0 * math.pi * f * t
    a = _signal(t, f, 5.0) + 2.0 * np.sin(w / 3.0 + 0.3) + 1.0 * np.cos(2.0 * w / 3.0)
    six = _feed(LineAmplitude(AmplitudeSettings()), t, a, f)
    assert [m.amplitude_mps2 for m in six] == pytest.approx([5.0] * len(six), rel=1e-9)
    eight = _feed(LineAmplitude(AmplitudeSettings(window_periods=8)), t, a, f)
    assert max(abs(m.amplitude_mps2 / 5.0 - 1.0) for m in eight) > 0.01


def test_a_frequency_change_restarts_the_window() -> None:
    line = LineAmplitude(AmplitudeSettings(window_periods=4))
    t1 = np.arange(0, 100) / RATE_HZ  # 0.1 s at 30 Hz: less than a window (0.133 s)
    assert _feed(line, t1, _signal(t1, 30.0, 50.0), 30.0) == []
    t2 = np.arange(100, 700) / RATE_HZ  # then 25 Hz at another amplitude
    got = _feed(line, t2, _signal(t2, 25.0, 5.0), 25.0)
    # windows of 4 / 25 Hz = 0.16 s from the first 25 Hz sample at 0.1 s, none mixing in 30 Hz
    assert [m.t_s for m in got] == pytest.approx([0.26, 0.42, 0.58])
    assert [m.amplitude_mps2 for m in got] == pytest.approx([5.0] * 3, rel=1e-9)


def test_non_finite_samples_are_dropped_and_counted() -> None:
    t = np.arange(1, 601) / RATE_HZ
    a = _signal(t, 30.0, 7.0)
    a[[10, 200, 201, 450]] = np.nan
    a[300] = np.inf
    t[500] = np.nan
    line = LineAmplitude(AmplitudeSettings(window_periods=8))
    got = _feed(line, t, a, 30.0)
    assert line.dropped == 6
    assert len(got) == 2
    assert [m.amplitude_mps2 for m in got] == pytest.approx([7.0, 7.0], rel=1e-9)


# -- the regulator --------------------------------------------------------------------------
def _window(
    t_s: float, amplitude: float, f: float = 30.0, residual: float = 0.1
) -> AmplitudeMeasurement:
    return AmplitudeMeasurement(t_s, f, amplitude, residual)


def _regulator(
    plant: float = 0.8, applied: float = 40.0, **settings: Any
) -> tuple[AmplitudeRegulator, float]:
    """A regulator that has seen two windows at ``applied`` % of a plant of ``plant`` m/s^2 per %,
    and the end of the next window."""
    reg = AmplitudeRegulator(AmplitudeSettings(**settings), 100.0)
    length = reg.settings.window_periods / 30.0
    for k in (1, 2):
        reg.update(_window(k * length, plant * applied), applied)
    return reg, 3 * length


def test_set_points_that_cannot_be_met_are_refused_and_change_nothing() -> None:
    reg = AmplitudeRegulator(AmplitudeSettings(), 100.0)
    assert reg.reachable_max_mps2(30.0) is None  # nothing measured: any reach is unknown
    assert reg.set_point(50.0, None) == ""
    assert "nan" in reg.set_point(math.nan, None)
    assert reg.set_point(-1.0, None) == "amplitude set point -1 m/s^2 must be > 0"
    reg, _ = _regulator(plant=2.124)
    assert reg.reachable_max_mps2(30.0) == pytest.approx(212.4)
    assert reg.reachable_max_mps2(30.2) == pytest.approx(212.4)  # about the same frequency
    assert reg.reachable_max_mps2(40.0) is None
    assert reg.set_point(100.0, reg.reachable_max_mps2(30.0)) == ""
    refusal = reg.set_point(300.0, reg.reachable_max_mps2(30.0))
    assert (
        refusal
        == "amplitude set point 300 m/s^2 beyond the drive's reach: 0 .. 212.4 m/s^2 at 30 Hz"
    )
    assert reg.set_point_mps2 == 100.0


def test_relaxation_and_step_limit() -> None:
    reg, t = _regulator(plant=0.8, applied=40.0, gain=0.7, max_step_percent=10.0)
    assert reg.set_point(36.0, None) == ""  # needs 45 %: 70 % of the 5 % correction
    out = reg.update(_window(t, 32.0), 40.0)
    assert out.amplitude_percent == pytest.approx(43.5)
    assert not out.limited
    assert out.reason == ""
    # the window in which the amplitude changed is skipped: the command is held
    length = reg.settings.window_periods / 30.0
    held = reg.update(_window(t + length, 99.0), 43.5)
    assert held.amplitude_percent == pytest.approx(43.5)
    assert reg.reachable_max_mps2(30.0) == pytest.approx(80.0)  # the odd window taught nothing
    assert reg.set_point(48.0, None) == ""  # needs 60 %: 0.7 * 16.5 % limited to 10 %
    out = reg.update(_window(t + 2 * length, 0.8 * 43.5), 43.5)
    assert out.amplitude_percent == pytest.approx(53.5)


def test_at_the_limit_the_command_does_not_wind_up_and_leaves_at_once() -> None:
    reg, t = _regulator(plant=0.8, applied=40.0, gain=1.0, max_step_percent=100.0)
    assert reg.set_point(80.0, None) == ""
    length = reg.settings.window_periods / 30.0
    out = reg.update(_window(t, 32.0), 40.0)
    assert out.amplitude_percent == 100.0
    applied = 100.0
    for k in range(1, 20):  # the plant gets softer: 104 % then 130 % would be needed
        gain = 0.77 if k < 10 else 0.8 / 1.3
        out = reg.update(_window(t + k * length, gain * applied), applied)
        assert out.amplitude_percent <= 100.0
    assert out.limited
    assert out.reason == "set point 80 m/s^2 needs 130 % > max 100 %: holding 100 %"
    # reachable again: the first window leaves the limit, by the full correction (no windup)
    out = reg.update(_window(t + 20 * length, 0.95 * applied), applied)
    assert out.amplitude_percent == pytest.approx(80.0 / 0.95)
    assert not out.limited


def test_a_large_residual_is_reported_and_stale_feedback_holds() -> None:
    fresh = AmplitudeRegulator(AmplitudeSettings(), 100.0)
    assert fresh.stale(0.0)
    assert fresh.output(0.0, 30.0) == RegulatorOutput(
        30.0, False, "no measurement yet: holding 30 %"
    )
    reg, t = _regulator()
    reg.set_point(32.0, None)
    quiet = reg.update(_window(t, 32.0, residual=30.0), 40.0)  # a bilinear carrier's harmonics
    assert quiet.reason == ""
    length = reg.settings.window_periods / 30.0
    t += length
    out = reg.update(_window(t, 32.0, residual=40.0), 40.0)
    assert out.amplitude_percent == pytest.approx(40.0)
    assert out.reason.startswith("residual 40 m/s^2 exceeds 1 x the 32 m/s^2 line at 30 Hz")
    assert not reg.stale(t + 1.0)
    assert reg.output(t + 0.5, 41.0) == out  # between measurements: the latest command
    assert reg.stale(t + 1.01)
    stale = reg.output(t + 1.5, 41.0)
    assert stale.amplitude_percent == 41.0
    assert "stale" in stale.reason


# -- closed loop on the exact physics -------------------------------------------------------
F_HZ = 30.0  # near the paper's 29.6 Hz; this carrier runs a period-3 orbit here (10 Hz lines)
FULL_SCALE_N = 100.0  # force at 100 % (DriveLimits' default): the damped carrier needs tens of N
MAX_PERCENT = 60.0  # the drive's amplitude limit
RAMP_PERCENT_PER_S = 50.0  # the drive's amplitude rate limit (DriveLimits' default)
SET_POINT_MPS2 = 5.0  # well above the parts' stick limit mu_s * g = 1.96 m/s^2: they feed


class _Drive:
    """The drive between regulator and simulator: amplitude % to force, ramped at the drive's
    rate limit, and the % it applies at any time (what the node reads back from its drive)."""

    def __init__(self, sim: FeederSimulator) -> None:
        self.sim = sim
        self.start_s, self.start_percent, self.target_percent = 0.0, 0.0, 0.0

    def applied(self, t_s: float) -> float:
        ramp_s = abs(self.target_percent - self.start_percent) / RAMP_PERCENT_PER_S
        if t_s >= self.start_s + ramp_s:
            return self.target_percent
        share = (t_s - self.start_s) / ramp_s
        return self.start_percent + share * (self.target_percent - self.start_percent)

    def command(self, percent: float) -> None:
        now = self.sim.time_s
        self.start_percent, self.start_s = self.applied(now), now
        self.target_percent = percent
        ramp_s = abs(percent - self.start_percent) / RAMP_PERCENT_PER_S
        self.sim.set_drive(F_HZ, percent / 100.0 * FULL_SCALE_N, ramp_s=ramp_s)


def test_closed_loop_holds_the_amplitude_through_a_live_stiffness_drop() -> None:
    """The realistic preset's damped carrier (c = 200 N*s/m) with one part, read by a noisy,
    biased, tilted accelerometer at 1 kHz; the loop starts from a stopped drive, settles, and
    when the springs lose 15 % of their stiffness live it brings the line back within 2 %."""
    params = FeederParameters(damping_ns_per_m=200.0, drive_frequency_hz=F_HZ)
    sim = FeederSimulator(params)
    drive = _Drive(sim)
    drive.command(0.0)
    imu = AccelerometerModel(RATE_HZ, noise_density=0.0015, bias=0.04, misalignment_deg=1.5)
    settings = AmplitudeSettings()
    line, regulator = LineAmplitude(settings), AmplitudeRegulator(settings, MAX_PERCENT)
    assert regulator.set_point(SET_POINT_MPS2, None) == ""
    drop_s, end_s = 5.0, 7.5
    history: list[tuple[float, float, float]] = []  # window end, measured line, command
    tick = 0
    while sim.time_s < end_s:
        tick += 1  # the node's 10 ms ticks; samples on the IMU's grid k / rate
        times = np.arange(10 * tick - 9, 10 * tick + 1) / RATE_HZ
        result = sim.advance(tick / 100.0, times)
        if math.isclose(sim.time_s, drop_s):
            softer = params.with_changes(youngs_modulus_pa=0.85 * params.youngs_modulus_pa)
            sim.set_parameters(softer)
        measured = imu.measure(result.carrier_a_mps2)[:, 0]  # x: along the track
        for m in line.add(times, measured, F_HZ):
            out = regulator.update(m, drive.applied(m.t_s))
            history.append((m.t_s, m.amplitude_mps2, out.amplitude_percent))
            if out.amplitude_percent != drive.target_percent:
                drive.command(out.amplitude_percent)
    t, measured, command = (np.array(column) for column in zip(*history, strict=True))
    assert command.max() <= MAX_PERCENT
    off = np.abs(measured / SET_POINT_MPS2 - 1.0)
    before = (t > drop_s - 1.0) & (t <= drop_s)
    assert off[before].max() < 0.02  # settled before the drop
    after = t > drop_s
    assert off[after].max() > 0.05  # the drop disturbed it
    last_miss = t[after & (off >= 0.02)].max()
    within = t[after & (t > last_miss)]  # window ends from the first one of the final good run
    assert within.size > 5, f"the line never stayed within 2 % (last miss at {last_miss:.2f} s)"
    recovery_s = within[0] - drop_s
    print(f"recovered within 2 % {recovery_s:.2f} s after the stiffness drop")
    assert recovery_s <= 2.0
