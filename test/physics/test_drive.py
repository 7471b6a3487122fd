"""Drive schedule: phase-continuous piecewise sinusoid, ramps as exact staircases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from feeder_ros.physics.drive import DriveChange, DriveError, DriveSchedule


def test_constant_drive_is_a_sine() -> None:
    drive = DriveSchedule(29.6, 40.0)
    t = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(drive.force(t), 40.0 * np.sin(2 * np.pi * 29.6 * t), atol=1e-12)


def test_phase_is_continuous_across_a_change() -> None:
    drive = DriveSchedule(29.6, 10.0, (DriveChange(0.0123, 47.0, 20.0),))
    seg = drive.segments()
    assert seg.start_s.tolist() == [0.0, 0.0123]
    phase_before = seg.phase_rad[0] + seg.omega_rad_s[0] * 0.0123
    assert math.isclose(
        math.sin(phase_before), math.sin(seg.phase_rad[1]), rel_tol=0.0, abs_tol=1e-12
    )
    # just before and after: the same phase, only the amplitude jumps
    before = drive.force(np.nextafter(0.0123, 0.0)) / 10.0
    after = drive.force(0.0123) / 20.0
    assert math.isclose(float(before), float(after), abs_tol=1e-9)


def test_ramp_is_a_staircase_reaching_the_target_at_its_end() -> None:
    drive = DriveSchedule(30.0, 0.0, (DriveChange(0.1, 40.0, 10.0, ramp_s=0.01),))
    seg = drive.segments()
    assert seg.start_s.size == 1 + 10
    np.testing.assert_allclose(np.diff(seg.start_s[1:]), 0.001, rtol=1e-9)
    freqs = seg.omega_rad_s / (2 * np.pi)
    assert np.all(np.diff(freqs) > 0.0)
    assert np.all(np.diff(seg.amplitude_n) > 0.0)
    assert drive.values_at(0.11) == pytest.approx((40.0, 10.0))
    assert drive.values_at(0.1055) == pytest.approx((36.0, 6.0))
    assert seg.logged.tolist() == [0, 1] + [0] * 9


def test_a_new_change_supersedes_the_rest_of_a_ramp() -> None:
    drive = DriveSchedule(30.0, 0.0, (DriveChange(0.1, 40.0, 10.0, ramp_s=0.01),))
    cut = drive.with_change(DriveChange(0.1055, 50.0, 5.0))
    seg = cut.segments()
    assert seg.start_s[-1] == 0.1055
    assert cut.values_at(0.2) == (50.0, 5.0)
    assert cut.values_at(0.1054) == drive.values_at(0.1054)


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"frequency_hz": -1.0, "amplitude_n": 1.0}, "frequency_hz=-1.0"),
        ({"frequency_hz": 30.0, "amplitude_n": math.nan}, "amplitude_n=nan"),
        ({"frequency_hz": 0.0, "amplitude_n": 1.0}, "frequency_hz=0.0"),
    ],
)
def test_bad_drive_values_are_refused(kwargs: dict[str, float], needle: str) -> None:
    with pytest.raises(DriveError, match=needle.replace("(", r"\(")):
        DriveSchedule(**kwargs)


def test_changes_out_of_order_are_refused() -> None:
    with pytest.raises(DriveError, match="time order"):
        DriveSchedule(30.0, 1.0, (DriveChange(0.2, 30.0, 1.0), DriveChange(0.1, 30.0, 1.0)))
    with pytest.raises(DriveError, match="ramp_s=-1"):
        DriveChange(0.1, 30.0, 1.0, ramp_s=-1.0)
