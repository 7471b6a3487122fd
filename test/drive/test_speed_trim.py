"""The speed trim: when it trusts a reading, how far it steps, never below zero amplitude."""

from __future__ import annotations

import math

import pytest

from feeder_ros.drive.speed_trim import SpeedTrim, TrimSettings
from feeder_ros.physics.parameters import ParameterError

TARGET = 0.010  # m/s


def _trim(**settings: float) -> SpeedTrim:
    trim = SpeedTrim(TrimSettings(**settings))
    trim.setting_changed(1.0)  # the setting is reached at t = 1 s
    return trim


def test_readings_it_cannot_trust_or_that_span_the_change_are_not_used() -> None:
    trim = _trim()
    assert trim.reading(3.0, 1.0, 0.008, 0.001, TARGET, 40.0) is None  # 10 % of the target
    assert trim.last_note.startswith("estimate too uncertain to trim on")
    assert trim.reading(1.5, 1.0, 0.008, 1e-5, TARGET, 40.0) is None  # window from 0.5 s
    assert trim.last_note == "waiting for an estimate of the current setting"
    assert trim.reading(3.0, 1.0, math.nan, 1e-5, TARGET, 40.0) is None
    assert trim.last_note == "waiting for a valid estimate"
    assert trim.reading(3.0, 1.0, 0.00998, 1e-5, TARGET, 40.0) is None
    assert trim.last_note == "on target (+0.20 %)"


def test_a_step_is_the_gain_times_the_error_within_max_step() -> None:
    trim = _trim(gain=0.5, max_step=0.15)
    assert trim.reading(3.0, 1.0, 0.009, 1e-5, TARGET, 40.0) == pytest.approx(40.0 * 1.05)
    assert trim.reading(3.0, 1.0, 0.009, 1e-5, TARGET, 40.0) is None  # until the next setting
    trim.setting_changed(4.0)
    assert trim.reading(6.0, 1.0, 0.005, 1e-5, TARGET, 40.0) == pytest.approx(40.0 * 1.15)
    assert trim.steps == 2


def test_a_large_overspeed_never_asks_for_a_negative_amplitude() -> None:
    """max_step may be up to 2 (a doubling up); down, the amplitude stops at zero."""
    trim = _trim(gain=2.0, max_step=2.0)
    assert trim.reading(3.0, 1.0, 0.030, 1e-5, TARGET, 40.0) == 0.0
    with pytest.raises(ParameterError, match=r"max_step=2\.5"):
        TrimSettings(max_step=2.5)
