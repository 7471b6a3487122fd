"""Drive schedule: phase-continuous piecewise sinusoid, ramps as exact staircases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from feeder_ros.physics.drive import MAX_RAMP_STEPS, DriveChange, DriveError, DriveSchedule


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


@pytest.mark.parametrize(("ramp_s", "step_s"), [(1e6, 1e-3), (1e9, 1e-3), (1.0, 1e-300)])
def test_a_ramp_is_cut_into_at_most_max_ramp_steps(ramp_s: float, step_s: float) -> None:
    drive = DriveSchedule(
        30.0, 0.0, (DriveChange(0.1, 40.0, 10.0, ramp_s=ramp_s),), ramp_step_s=step_s
    )
    seg = drive.segments()
    assert seg.start_s.size == 1 + MAX_RAMP_STEPS
    # still a staircase reaching the target at the ramp's end, in equal steps
    assert drive.values_at(0.1 + ramp_s) == pytest.approx((40.0, 10.0))
    np.testing.assert_allclose(np.diff(seg.start_s[1:]), ramp_s / MAX_RAMP_STEPS, rtol=1e-6)


@pytest.mark.parametrize("name", ["time_s", "ramp_s"])
def test_change_times_and_ramps_beyond_max_time_are_refused(name: str) -> None:
    values = {"time_s": 0.0, "frequency_hz": 30.0, "amplitude_n": 1.0, "ramp_s": 0.0}
    with pytest.raises(DriveError, match=f"{name}=1e\\+308 must be <= 1e\\+09"):
        DriveChange(**{**values, name: 1e308})


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


def _busy_schedule() -> DriveSchedule:
    """Ramps cut by the next change, changes sharing an instant, a change without a ramp."""
    drive = DriveSchedule(30.0, 0.0)
    rng = np.random.default_rng(7)
    t = 0.0
    for k in range(40):
        t += float(rng.choice([0.004, 0.013, 0.0])) if k else 0.05
        ramp = float(rng.choice([0.0, 0.01, 0.03]))
        drive = drive.with_change(
            DriveChange(t, 30.0 + float(rng.uniform(-3, 3)), float(rng.uniform(0, 40)), ramp)
        )
    return drive


@pytest.mark.parametrize("at", [0.0, 0.05, 0.1234, 0.2, 0.2461, 0.3, 0.5, 9.0])
def test_forget_before_keeps_the_drive_from_then_on_bit_for_bit(at: float) -> None:
    drive = _busy_schedule()
    last = drive.changes[-1]
    assert last.time_s + last.ramp_s > 0.3  # (the schedule spans the instants tried)
    short = drive.forget_before(at)
    full, kept = drive.segments(), short.segments()
    assert kept.start_s[0] <= at
    assert all(change.time_s > kept.start_s[0] for change in short.changes)
    # from the segment in force at `at` on, the very same numbers
    k_full, k_kept = full.index_at(at), kept.index_at(at)
    assert full.start_s.size - k_full == kept.start_s.size - k_kept
    for name in ("start_s", "omega_rad_s", "amplitude_n", "phase_rad", "frequency_hz"):
        assert getattr(kept, name)[k_kept:].tolist() == getattr(full, name)[k_full:].tolist()
    assert kept.logged[k_kept + 1 :].tolist() == full.logged[k_full + 1 :].tolist()
    t = np.linspace(at, 0.6, 2001)
    assert short.force(t).tolist() == drive.force(t).tolist()
    # and a new change on top of either gives the same drive again
    change = DriveChange(max(at, 0.31), 28.0, 12.0, ramp_s=0.02)
    a, b = drive.with_change(change).segments(), short.with_change(change).segments()
    k_a, k_b = a.index_at(at), b.index_at(at)
    assert a.phase_rad[k_a:].tolist() == b.phase_rad[k_b:].tolist()
    assert a.start_s[k_a:].tolist() == b.start_s[k_b:].tolist()


def test_forget_before_forgets_what_lies_before_and_nothing_else() -> None:
    drive = _busy_schedule()
    assert drive.forget_before(0.0) is drive  # nothing in the past yet
    assert drive.forget_before(0.05) is drive  # the first change is the one in force
    short = drive.forget_before(0.3)
    assert len(short.changes) < len(drive.changes)
    assert short.changes == drive.changes[-len(short.changes) :]
    assert short.forget_before(0.3) is short  # idempotent
    assert short.segments().start_s.size < drive.segments().start_s.size


def test_a_schedule_start_and_its_phase_are_checked() -> None:
    with pytest.raises(DriveError, match=r"start_phase_rad=7\.0"):
        DriveSchedule(30.0, 1.0, start_s=1.0, start_phase_rad=7.0)
    with pytest.raises(DriveError, match=r"a change at 0\.5 s is before start_s=1\.0"):
        DriveSchedule(30.0, 1.0, (DriveChange(0.5, 30.0, 1.0),), start_s=1.0)
    with pytest.raises(DriveError, match="start_s=nan"):
        DriveSchedule(30.0, 1.0, start_s=math.nan)
