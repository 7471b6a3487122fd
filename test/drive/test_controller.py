"""The drive interface's state machine, driven with explicit times (no ROS, no clock)."""

from __future__ import annotations

import math

import pytest

from feeder_ros.drive.controller import DriveController, DriveState
from feeder_ros.drive.limits import DriveLimits, Outcome
from feeder_ros.drive.speed_model import TableSpeedModel

LIMITS = DriveLimits(max_frequency_rate_hz_per_s=10.0, max_amplitude_rate_percent_per_s=25.0)


def running_controller(now: float = 0.0, timeout: float = 2.0) -> DriveController:
    controller = DriveController(LIMITS, heartbeat_timeout_s=timeout)
    controller.activate(now)
    controller.heartbeat(now)
    answer = controller.set_drive(now, 30.0, 50.0, 0.0)
    assert answer.outcome is Outcome.ACCEPTED, answer
    assert controller.start(now).success
    return controller


def test_start_ramps_up_then_runs_at_the_set_point() -> None:
    c = running_controller()
    out = c.tick(0.0, 0.02)
    assert c.state is DriveState.RAMPING
    assert not out.enabled
    out = c.tick(1.0, 0.02)
    assert c.state is DriveState.RAMPING
    assert out.enabled
    assert out.amplitude_percent == pytest.approx(25.0)
    assert out.amplitude_n == pytest.approx(25.0)
    assert out.ramp_time_s == 0.02  # the receiver interpolates between ticks
    c.heartbeat(1.5)
    out = c.tick(2.5, 0.02)
    assert c.state is DriveState.RUNNING
    assert (out.frequency_hz, out.amplitude_percent, out.ramp_time_s) == (30.0, 50.0, 0.0)


def test_set_drive_while_stopped_stores_and_reports_the_ramp_it_will_use() -> None:
    c = DriveController(LIMITS)
    c.activate(0.0)
    answer = c.set_drive(0.0, 30.0, 50.0, 0.5)
    assert answer.outcome is Outcome.ACCEPTED
    assert answer.ramp_time_s == pytest.approx(2.0)
    assert "set point stored; start to drive" in answer.reason
    assert "lengthened from 0.5 s to 2.000 s" in answer.reason
    assert not c.tick(1.0).enabled
    assert c.state is DriveState.IDLE


def test_clamped_set_drive_drives_the_clamped_values() -> None:
    c = running_controller()
    c.heartbeat(3.0)
    answer = c.set_drive(3.0, 500.0, 50.0, 0.0)
    assert answer.outcome is Outcome.CLAMPED
    assert answer.frequency_hz == 300.0
    assert "clamped to 300 Hz" in answer.reason
    assert c.tick(3.0 + answer.ramp_time_s).frequency_hz == 300.0
    assert answer.ramp_time_s == pytest.approx(27.0)  # 270 Hz at 10 Hz/s


@pytest.mark.parametrize(
    ("prepare", "fragment"),
    [
        ("inactive", "not active"),
        ("no_heartbeat", "no heartbeat received"),
        ("no_set_point", "set point amplitude is 0 %"),
        ("estop", "emergency stop latched"),
    ],
)
def test_start_refusals_say_why(prepare: str, fragment: str) -> None:
    c = DriveController(LIMITS)
    if prepare != "inactive":
        c.activate(0.0)
    if prepare != "no_heartbeat":
        c.heartbeat(0.0)
    if prepare != "no_set_point":
        c.set_drive(0.0, 30.0, 40.0, 0.0)
    if prepare == "estop":
        c.emergency_stop(0.0)
    answer = c.start(0.0)
    assert not answer.success
    assert fragment in answer.message
    assert not c.tick(1.0).enabled


def test_stop_ramps_down_then_idles() -> None:
    c = running_controller()
    c.heartbeat(3.0)
    assert c.tick(3.0).amplitude_percent == 50.0
    answer = c.stop(3.0)
    assert answer.success
    assert "ramping to zero in 2.000 s" in answer.message
    assert c.tick(4.0).amplitude_percent == pytest.approx(25.0)
    assert c.state is DriveState.RAMPING
    out = c.tick(5.0)
    assert not out.enabled
    assert out.amplitude_n == 0.0
    assert c.state is DriveState.IDLE
    assert c.stop(6.0).message == "already stopped"


def test_watchdog_trips_to_fault_and_ramps_down_when_heartbeats_stop() -> None:
    c = running_controller(timeout=2.0)
    c.heartbeat(3.0)
    assert c.tick(4.9).amplitude_percent == 50.0
    assert c.state is DriveState.RUNNING
    out = c.tick(5.05)  # last beat at 3.0 s, timeout 2 s
    assert c.state is DriveState.FAULT
    assert "heartbeat lost" in c.fault_reason
    assert "timeout 2 s" in c.fault_reason
    assert out.amplitude_percent == pytest.approx(50.0)  # ramps, does not step
    assert c.tick(6.05).amplitude_percent == pytest.approx(25.0)
    assert not c.tick(7.1).enabled
    assert c.state is DriveState.FAULT
    c.heartbeat(8.0)
    refused = c.start(8.0)
    assert not refused.success
    assert "fault latched (heartbeat lost" in refused.message
    assert c.reset_fault(8.0).success
    assert c.start(8.0).success
    assert c.tick(9.0).enabled


def test_emergency_stop_zeroes_at_once_and_latches_until_reset() -> None:
    c = running_controller()
    c.heartbeat(3.0)
    assert c.tick(3.0).amplitude_percent == 50.0
    assert c.emergency_stop(3.0).success
    out = c.tick(3.0)
    assert not out.enabled
    assert out.amplitude_percent == 0.0
    assert c.state is DriveState.ESTOP
    assert c.fault_reason == "emergency stop requested"
    assert c.set_drive(3.1, 30.0, 20.0, 0.0).outcome is Outcome.REFUSED
    assert not c.start(3.1).success
    c.fault(3.2, "something else")  # a fault does not replace a latched e-stop
    assert c.tick(3.2)
    assert c.state is DriveState.ESTOP
    answer = c.reset_fault(3.3)
    assert answer.success
    assert "emergency stop requested" in answer.message
    assert c.tick(3.3)
    assert c.state is DriveState.IDLE
    assert c.reset_fault(3.4).message == "no fault to reset"


def test_backend_fault_zeroes_and_blocks_reset_until_it_clears() -> None:
    c = running_controller()
    c.heartbeat(3.0)
    c.tick(3.0)
    c.set_backend_fault(3.0, "controller alarm (code 7)")
    assert not c.tick(3.0).enabled
    assert c.state is DriveState.FAULT
    assert c.fault_reason == "backend: controller alarm (code 7)"
    answer = c.reset_fault(3.5)
    assert not answer.success
    assert "backend still faulted" in answer.message
    c.set_backend_fault(4.0, "")
    assert c.reset_fault(4.0).success


def test_deactivate_ramps_to_zero_and_refuses_new_commands() -> None:
    c = running_controller()
    c.heartbeat(3.0)
    c.tick(3.0)
    assert c.deactivate(3.0) == pytest.approx(2.0)
    assert c.tick(4.0).amplitude_percent == pytest.approx(25.0)
    assert not c.tick(5.0).enabled
    assert c.state is DriveState.IDLE
    assert "not active" in c.set_drive(5.0, 30.0, 10.0, 0.0).reason


def test_limit_change_clamps_the_running_set_point() -> None:
    c = running_controller()
    c.heartbeat(3.0)
    c.tick(3.0)
    note = c.update_limits(
        DriveLimits(max_amplitude_percent=30.0, max_amplitude_rate_percent_per_s=10.0), 3.0
    )
    assert "clamped to 30 %" in note
    assert c.tick(4.0).amplitude_percent == pytest.approx(40.0)  # down at the new 10 %/s
    assert c.tick(5.0).amplitude_percent == pytest.approx(30.0)


def test_limit_change_on_an_idle_or_stopping_drive_latches_no_fault() -> None:
    # active, never started: the output rests at the default set point's frequency, zero force
    idle = DriveController(LIMITS)
    idle.activate(0.0)
    resting = idle.tick(0.0)
    assert not resting.enabled
    raised = resting.frequency_hz + 10.0
    idle.update_limits(DriveLimits(min_frequency_hz=raised), 1.0)
    out = idle.tick(1.0)
    assert idle.state is DriveState.IDLE, idle.fault_reason
    assert not idle.fault_reason
    assert (out.enabled, out.frequency_hz) == (False, raised)
    # stopped while still ramping down: the soft stop goes on, into the new limits
    c = running_controller()
    c.heartbeat(3.0)
    assert c.tick(3.0).amplitude_percent == pytest.approx(50.0)
    c.stop(3.0)
    c.update_limits(
        DriveLimits(
            max_frequency_hz=25.0,
            max_frequency_rate_hz_per_s=10.0,
            max_amplitude_rate_percent_per_s=25.0,
        ),
        3.0,
    )
    c.heartbeat(3.5)
    out = c.tick(3.5)
    assert c.state is DriveState.RAMPING, c.fault_reason
    assert 0.0 < out.amplitude_percent < 50.0
    assert 25.0 < out.frequency_hz < 30.0  # on its way down at the frequency rate
    c.heartbeat(6.0)
    out = c.tick(6.0)
    assert c.state is DriveState.IDLE, c.fault_reason
    assert (out.enabled, out.frequency_hz) == (False, 25.0)


def test_target_speed_uses_the_model_and_refuses_or_clamps_the_unreachable() -> None:
    table = TableSpeedModel(
        [20.0, 30.0], [0.0, 50.0, 100.0], [[0.0, 0.01, 0.02], [0.0, 0.02, 0.05]]
    )
    c = DriveController(LIMITS, speed_model=table)
    c.activate(0.0)
    answer = c.set_target_speed(0.0, 0.02, 0.0)
    assert answer.outcome is Outcome.ACCEPTED
    # the best-predicted bracket: 10..20 mm/s at 20 Hz rather than 0..20 at 30 Hz
    assert (answer.frequency_hz, answer.amplitude_percent) == (20.0, 100.0)
    assert answer.predicted_speed_mps == pytest.approx(0.02)
    assert c.speed_mode
    refused = c.set_target_speed(0.0, 0.08, 0.0)
    assert refused.outcome is Outcome.REFUSED
    assert "reachable 0 .. 0.05 m/s" in refused.reason
    c.clamp_unreachable_speed = True
    clamped = c.set_target_speed(0.0, 0.08, 0.0)
    assert clamped.outcome is Outcome.CLAMPED
    assert clamped.predicted_speed_mps == pytest.approx(0.05)
    assert (clamped.frequency_hz, clamped.amplitude_percent) == (30.0, 100.0)
    c.set_drive(0.0, 30.0, 10.0, 0.0)
    assert not c.speed_mode
    no_model = DriveController(LIMITS)
    no_model.activate(0.0)
    assert "no speed model" in no_model.set_target_speed(0.0, 0.01, 0.0).reason


@pytest.mark.parametrize(
    ("frequency", "amplitude", "reason"),
    [
        (-20.0, 50.0, "frequency_hz=-20 must be > 0 Hz"),
        (0.0, 50.0, "frequency_hz=0 must be > 0 Hz"),
        (math.nan, 50.0, "frequency_hz=nan is not finite"),
        (30.0, -5.0, "amplitude_percent=-5 must be >= 0 %"),
    ],
)
def test_impossible_set_drive_is_refused_and_changes_nothing(
    frequency: float, amplitude: float, reason: str
) -> None:
    c = running_controller()
    c.heartbeat(3.0)
    before = c.tick(3.0)
    answer = c.set_drive(3.0, frequency, amplitude, 0.0)
    assert answer.outcome is Outcome.REFUSED
    assert answer.reason.startswith(reason)
    assert (c.set_point.frequency_hz, c.set_point.amplitude_percent) == (30.0, 50.0)
    after = c.tick(3.5)
    assert (after.enabled, after.frequency_hz, after.amplitude_percent) == (True, 30.0, 50.0)
    assert (before.frequency_hz, before.amplitude_percent) == (30.0, 50.0)
    assert c.state is DriveState.RUNNING


def test_target_speed_refuses_non_finite_speeds_and_treats_negative_ones_as_unreachable() -> None:
    """A NaN or infinite speed is refused naming it; a negative speed is a direction a feeder
    may or may not have: the speed model decides (this one has no backward speed: refused with the
    reachable range; with unreachable_speed=clamp the nearest reachable speed, 0 m/s)."""
    table = TableSpeedModel(
        [20.0, 30.0], [0.0, 50.0, 100.0], [[0.0, 0.01, 0.02], [0.0, 0.02, 0.05]]
    )
    c = DriveController(LIMITS, speed_model=table)
    c.activate(0.0)
    for speed in (math.nan, math.inf, -math.inf):
        refused = c.set_target_speed(0.0, speed, 0.0)
        assert refused.outcome is Outcome.REFUSED
        assert f"speed_mps={speed!r}" in refused.reason
    backwards = c.set_target_speed(0.0, -0.01, 0.0)
    assert backwards.outcome is Outcome.REFUSED
    assert "speed -0.01 m/s unreachable within the limits; reachable 0 .. 0.05 m/s" in (
        backwards.reason
    )
    assert not c.speed_mode
    c.clamp_unreachable_speed = True
    clamped = c.set_target_speed(0.0, -0.01, 0.0)
    assert clamped.outcome is Outcome.CLAMPED
    assert clamped.predicted_speed_mps == 0.0
    assert clamped.amplitude_percent == 0.0


def test_a_hold_ramps_feeding_to_zero_and_its_release_ramps_back() -> None:
    c = running_controller()
    c.heartbeat(2.5)
    assert c.tick(2.5, 0.02).amplitude_percent == 50.0  # running at the set point
    c.hold(3.0, "level", "track full")
    assert c.paused
    assert c.hold_reason == "track full"
    out = c.tick(4.0, 0.02)  # 25 %/s: halfway down
    assert c.state is DriveState.RAMPING
    assert out.amplitude_percent == pytest.approx(25.0)
    c.heartbeat(5.0)
    out = c.tick(5.5, 0.02)
    assert c.state is DriveState.PAUSED
    assert not out.enabled
    assert out.frequency_hz == 30.0  # the frequency is held
    c.release(6.0, "level")
    assert not c.paused
    c.heartbeat(7.0)
    assert c.tick(7.0, 0.02).amplitude_percent == pytest.approx(25.0)
    assert c.tick(8.0, 0.02).amplitude_percent == 50.0
    assert c.state is DriveState.RUNNING


def test_a_new_set_point_while_paused_is_stored_and_used_on_release() -> None:
    c = running_controller()
    c.hold(0.0, "level", "track full")
    answer = c.set_drive(0.5, 40.0, 20.0, 0.0)
    assert answer.outcome is Outcome.ACCEPTED
    assert "feeding paused (track full)" in answer.reason
    c.heartbeat(1.0)
    assert not c.tick(1.0, 0.02).enabled  # still held at zero
    c.release(1.0, "level")
    c.heartbeat(3.0)
    out = c.tick(3.0, 0.02)
    assert (out.frequency_hz, out.amplitude_percent) == (40.0, 20.0)


def test_two_holds_release_only_when_both_end_and_stop_keeps_the_output_off() -> None:
    c = running_controller()
    c.hold(0.0, "level", "track full")
    c.hold(0.0, "feed", "goal done")
    c.release(0.1, "level")
    assert c.paused
    assert c.hold_reason == "goal done"
    c.heartbeat(1.0)
    assert not c.tick(1.0, 0.02).enabled
    c.stop(1.0)
    c.release(1.1, "feed")
    c.heartbeat(2.0)
    assert not c.tick(3.0, 0.02).enabled
    assert c.state is DriveState.IDLE


def test_start_while_held_answers_paused_and_does_not_drive() -> None:
    c = DriveController(LIMITS)
    c.activate(0.0)
    c.heartbeat(0.0)
    c.set_drive(0.0, 30.0, 50.0, 0.0)
    c.hold(0.0, "level", "track full: sensor 1 covered for 1.0 s")
    answer = c.start(0.0)
    assert answer.success
    assert "feeding paused (track full: sensor 1" in answer.message
    c.heartbeat(1.0)
    assert not c.tick(1.0, 0.02).enabled
    assert c.state is DriveState.PAUSED
    c.release(1.0, "level")
    assert c.tick(2.0, 0.02).amplitude_percent == pytest.approx(25.0)


def test_amplitude_scale_slews_at_the_rate_limit_is_clamped_and_ends_with_the_output() -> None:
    c = running_controller(timeout=100.0)
    c.tick(2.0, 0.02)
    assert c.tick(2.5, 0.02).amplitude_percent == 50.0
    c.scale_amplitude(0.8)  # the inner loop wants 40 %: at 25 %/s that takes 0.4 s
    outputs = [c.tick(2.5 + 0.1 * k, 0.1).amplitude_percent for k in range(1, 7)]
    assert outputs == pytest.approx([47.5, 45.0, 42.5, 40.0, 40.0, 40.0])
    assert c.set_point.amplitude_percent == 50.0  # the set point is not the loop's
    c.scale_amplitude(3.0)  # beyond max_amplitude_percent: the output stops there
    assert c.tick(20.0, 0.1).amplitude_percent == LIMITS.max_amplitude_percent
    for bad in (math.nan, -0.5, math.inf):
        with pytest.raises(ValueError, match=f"amplitude scale {bad!r}"):
            c.scale_amplitude(bad)
    c.scale_amplitude(0.8)
    c.tick(30.0, 0.1)
    c.emergency_stop(30.0)
    assert not c.tick(30.1, 0.1).enabled
    assert c.amplitude_scale == 1.0  # an output that went off forgets the correction
