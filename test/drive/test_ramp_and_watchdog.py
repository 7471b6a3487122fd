"""Ramp generator (rate-limited, linear, on an external time base) and heartbeat watchdog."""

from __future__ import annotations

import math

import numpy as np
import pytest

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.ramp import DrivePoint, Ramp
from feeder_ros.drive.watchdog import Watchdog

LIMITS = DriveLimits(max_frequency_rate_hz_per_s=10.0, max_amplitude_rate_percent_per_s=25.0)


def test_soft_start_steps_frequency_and_ramps_amplitude_at_the_rate_limit() -> None:
    ramp = Ramp(LIMITS)
    used = ramp.retarget(100.0, DrivePoint(30.0, 50.0), ramp_time_s=0.0)
    assert used == pytest.approx(2.0)  # 50 % at 25 %/s
    assert ramp.value(100.0) == DrivePoint(30.0, 0.0)
    assert ramp.value(101.0).amplitude_percent == pytest.approx(25.0)
    assert ramp.value(101.0).frequency_hz == 30.0
    assert ramp.value(102.0) == DrivePoint(30.0, 50.0)
    assert ramp.done(102.0)
    assert not ramp.done(101.9)


def test_longer_requested_ramp_is_kept_and_both_axes_arrive_together() -> None:
    ramp = Ramp(LIMITS)
    ramp.retarget(0.0, DrivePoint(30.0, 50.0), 0.0)
    used = ramp.retarget(10.0, DrivePoint(40.0, 20.0), ramp_time_s=4.0)
    assert used == 4.0  # slower than both limits (1 s and 1.2 s)
    times = np.linspace(10.0, 14.0, 41)
    f = np.array([ramp.value(t).frequency_hz for t in times])
    a = np.array([ramp.value(t).amplitude_percent for t in times])
    np.testing.assert_allclose(f, 30.0 + 10.0 * (times - 10.0) / 4.0, atol=1e-12)
    np.testing.assert_allclose(a, 50.0 - 30.0 * (times - 10.0) / 4.0, atol=1e-12)


def test_rates_never_exceed_the_limits() -> None:
    ramp = Ramp(LIMITS)
    ramp.retarget(0.0, DrivePoint(30.0, 80.0), 0.0)
    ramp.retarget(1.0, DrivePoint(150.0, 10.0), 0.5)  # retargeted mid-ramp
    times = np.linspace(1.0, 20.0, 2000)
    values = [ramp.value(t) for t in times]
    f = np.array([v.frequency_hz for v in values])
    a = np.array([v.amplitude_percent for v in values])
    dt = np.diff(times)
    assert np.max(np.abs(np.diff(f)) / dt) <= 10.0 * (1 + 1e-9)
    assert np.max(np.abs(np.diff(a)) / dt) <= 25.0 * (1 + 1e-9)
    assert values[-1] == DrivePoint(150.0, 10.0)


def test_soft_stop_holds_frequency_and_emergency_zero_is_immediate() -> None:
    ramp = Ramp(LIMITS)
    ramp.retarget(0.0, DrivePoint(30.0, 50.0), 0.0)
    assert ramp.to_zero(5.0) == pytest.approx(2.0)
    assert ramp.value(6.0) == DrivePoint(30.0, 25.0)
    ramp.zero_now(6.0)
    assert ramp.value(6.0) == DrivePoint(30.0, 0.0)
    assert ramp.done(6.0)


def test_clock_jumping_back_holds_the_start_value() -> None:
    ramp = Ramp(LIMITS)
    ramp.retarget(10.0, DrivePoint(30.0, 50.0), 0.0)
    assert ramp.value(5.0) == DrivePoint(30.0, 0.0)


def test_watchdog_expires_after_its_timeout_and_disables_at_zero() -> None:
    dog = Watchdog(2.0)
    assert not dog.alive(0.0)
    assert math.isinf(dog.age_s(0.0))
    dog.feed(10.0)
    assert dog.alive(11.99)
    assert dog.alive(12.0)
    assert not dog.alive(12.01)
    assert dog.age_s(12.5) == pytest.approx(2.5)
    dog.feed(12.5)
    assert dog.alive(13.0)
    assert Watchdog(0.0).alive(1e9)
    with pytest.raises(ValueError, match="timeout_s=-1"):
        Watchdog(-1.0)


def test_watchdog_treats_a_clock_jump_back_as_a_fresh_beat() -> None:
    dog = Watchdog(1.0)
    dog.feed(100.0)
    assert dog.alive(3.0)  # sim time restarted
    assert not dog.alive(4.5)
