"""Drive limits: validation, clamping of set points, forbidden bands, minimum ramp times."""

from __future__ import annotations

import math

import pytest

from feeder_ros.drive.limits import (
    DriveLimits,
    LimitError,
    Outcome,
    clamp_set_point,
    parse_bands,
    set_point_refusal,
)


def test_defaults_are_the_issue_s_limits() -> None:
    limits = DriveLimits()
    assert (limits.min_frequency_hz, limits.max_frequency_hz) == (5.0, 300.0)
    assert limits.max_amplitude_percent == 100.0
    assert limits.force_n(40.0) == pytest.approx(40.0)  # 100 N full scale, linear
    assert DriveLimits(full_scale_force_n=250.0).force_n(40.0) == pytest.approx(100.0)


@pytest.mark.parametrize(
    ("changes", "fragment"),
    [
        ({"min_frequency_hz": 300.0}, "must be below"),
        ({"max_amplitude_percent": 120.0}, "exceeds 100"),
        ({"max_frequency_rate_hz_per_s": 0.0}, "max_frequency_rate_hz_per_s=0.0"),
        ({"full_scale_force_n": math.nan}, "full_scale_force_n=nan"),
        ({"forbidden_bands_hz": ((60.0, 50.0),)}, "needs low < high"),
        ({"forbidden_bands_hz": ((0.0, 400.0),)}, "no frequency is allowed"),
    ],
)
def test_contradictory_limits_are_refused_with_the_value(changes: dict, fragment: str) -> None:
    with pytest.raises(LimitError, match=fragment):
        DriveLimits(**changes)


def test_in_range_set_point_is_accepted_unchanged() -> None:
    result = clamp_set_point(DriveLimits(), 30.0, 40.0, 1.5)
    assert result.outcome is Outcome.ACCEPTED
    assert result.reason == ""
    assert (result.frequency_hz, result.amplitude_percent, result.ramp_time_s) == (30.0, 40.0, 1.5)


def test_out_of_range_values_are_clamped_with_reasons() -> None:
    result = clamp_set_point(DriveLimits(), 400.0, 120.0, 0.0)
    assert result.outcome is Outcome.CLAMPED
    assert (result.frequency_hz, result.amplitude_percent) == (300.0, 100.0)
    assert "frequency 400 Hz outside 5-300 Hz, clamped to 300 Hz" in result.reason
    assert "amplitude 120 % outside 0-100 %, clamped to 100 %" in result.reason
    low = clamp_set_point(DriveLimits(), 1.0, 0.0, 0.0)
    assert low.outcome is Outcome.CLAMPED
    assert (low.frequency_hz, low.amplitude_percent) == (5.0, 0.0)
    assert low.reason == "frequency 1 Hz outside 5-300 Hz, clamped to 5 Hz"
    tiny = clamp_set_point(DriveLimits(), 1e-9, 10.0, 0.0)  # possible, however slow: clamped
    assert (tiny.outcome, tiny.frequency_hz) == (Outcome.CLAMPED, 5.0)


@pytest.mark.parametrize(
    ("frequency", "amplitude", "ramp", "reason"),
    [
        (math.nan, 10.0, 0.0, "frequency_hz=nan is not finite"),
        (math.inf, 10.0, 0.0, "frequency_hz=inf is not finite"),
        (-math.inf, 10.0, 0.0, "frequency_hz=-inf is not finite"),
        (-20.0, 10.0, 0.0, "frequency_hz=-20 must be > 0 Hz (this drive: 5-300 Hz)"),
        (0.0, 10.0, 0.0, "frequency_hz=0 must be > 0 Hz (this drive: 5-300 Hz)"),
        (-0.0, 10.0, 0.0, "frequency_hz=-0 must be > 0 Hz (this drive: 5-300 Hz)"),
        (30.0, math.inf, 0.0, "amplitude_percent=inf is not finite"),
        (30.0, math.nan, 0.0, "amplitude_percent=nan is not finite"),
        (30.0, -5.0, 0.0, "amplitude_percent=-5 must be >= 0 % (this drive: 0-100 %)"),
        (30.0, 10.0, -1.0, "ramp_time_s=-1 must be >= 0 s"),
        (30.0, 10.0, math.inf, "ramp_time_s=inf is not finite"),
        (
            -20.0,
            -5.0,
            math.nan,
            "frequency_hz=-20 must be > 0 Hz (this drive: 5-300 Hz); amplitude_percent=-5 "
            "must be >= 0 % (this drive: 0-100 %); ramp_time_s=nan is not finite",
        ),
    ],
)
def test_impossible_requests_are_refused_naming_each_value(
    frequency: float, amplitude: float, ramp: float, reason: str
) -> None:
    """No drive can run at a frequency <= 0 Hz, a negative amplitude, a negative or infinite ramp
    or a NaN: refused with every impossible value named, never clamped onto a real set point."""
    result = clamp_set_point(DriveLimits(), frequency, amplitude, ramp)
    assert result.outcome is Outcome.REFUSED
    assert result.reason == reason
    assert set_point_refusal(DriveLimits(), frequency, amplitude, ramp) == reason
    assert (result.frequency_hz, result.amplitude_percent, result.ramp_time_s) == (0.0, 0.0, 0.0)


def test_possible_requests_have_no_refusal() -> None:
    limits = DriveLimits()
    for request in ((30.0, 0.0, 0.0), (1e-9, 10.0, 0.0), (1e6, 150.0, 1e3)):
        assert set_point_refusal(limits, *request) == ""
        assert clamp_set_point(limits, *request).outcome is not Outcome.REFUSED


def test_forbidden_band_moves_the_set_point_to_the_nearest_edge() -> None:
    limits = DriveLimits(forbidden_bands_hz=((28.0, 34.0), (100.0, 120.0)))
    below = clamp_set_point(limits, 29.0, 10.0, 0.0)
    assert below.outcome is Outcome.CLAMPED
    assert below.frequency_hz == 28.0
    assert "in forbidden band 28-34 Hz, moved to 28 Hz" in below.reason
    above = clamp_set_point(limits, 33.0, 10.0, 0.0)
    assert above.frequency_hz == 34.0
    edge = clamp_set_point(limits, 34.0, 10.0, 0.0)
    assert edge.outcome is Outcome.ACCEPTED  # the edges themselves are allowed
    assert limits.allowed_intervals() == [(5.0, 28.0), (34.0, 100.0), (120.0, 300.0)]


def test_band_at_the_range_end_clamps_inward() -> None:
    limits = DriveLimits(forbidden_bands_hz=((250.0, 400.0),))
    result = clamp_set_point(limits, 350.0, 10.0, 0.0)
    assert result.frequency_hz == 250.0
    assert "clamped to 300 Hz" in result.reason
    assert "moved to 250 Hz" in result.reason


def test_minimum_ramp_time_follows_the_slower_axis() -> None:
    limits = DriveLimits(max_frequency_rate_hz_per_s=10.0, max_amplitude_rate_percent_per_s=20.0)
    assert limits.minimum_ramp_time_s(30.0, 40.0, 50.0, 40.0) == pytest.approx(2.0)
    assert limits.minimum_ramp_time_s(30.0, 0.0, 50.0, 60.0) == pytest.approx(3.0)
    # at zero amplitude the frequency may move freely: no force is applied
    assert limits.minimum_ramp_time_s(30.0, 0.0, 200.0, 0.0) == 0.0


def test_parse_bands_from_text_and_flat_lists() -> None:
    assert parse_bands("") == ()
    assert parse_bands("45, 55, 120,130") == ((45.0, 55.0), (120.0, 130.0))
    assert parse_bands([45.0, 55.0]) == ((45.0, 55.0),)
    with pytest.raises(LimitError, match="pairs"):
        parse_bands("45, 55, 120")
    with pytest.raises(LimitError, match="'abc' is not a number"):
        parse_bands("45, abc")
    with pytest.raises(LimitError, match="needs low < high"):
        parse_bands([55.0, 45.0])
