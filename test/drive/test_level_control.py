"""Track level control driven with explicit times (no ROS, no clock): delays, hysteresis, time-out,
settings refused with reasons, late edges and clock steps."""

from __future__ import annotations

import math

import pytest

from feeder_ros.drive.level_control import (
    LevelControl,
    LevelDecision,
    LevelError,
    LevelMode,
    LevelSettings,
    LevelState,
)

FULL, LOW = 1, 0  # sensor indices


def one_sensor(off: float = 1.0, on: float = 1.0, timeout: float = 0.0) -> LevelControl:
    settings = LevelSettings(LevelMode.ONE_SENSOR, FULL, LOW, off, on, timeout)
    control = LevelControl(settings)
    control.update(0.0, True)  # the first tick: timers count from here
    return control


def two_sensors(off: float = 1.0, on: float = 1.0, timeout: float = 0.0) -> LevelControl:
    settings = LevelSettings(LevelMode.TWO_SENSORS, FULL, LOW, off, on, timeout)
    control = LevelControl(settings)
    control.update(0.0, True)
    return control


def state_at(control: LevelControl, t: float, feeding: bool = True) -> LevelState:
    return control.update(t, feeding).state


def test_off_always_feeds_ignores_edges_and_never_faults() -> None:
    control = LevelControl(LevelSettings(sensor_timeout_s=1.0))
    assert control.settings.mode is LevelMode.OFF
    control.edge(0.0, FULL, True)
    for t in (0.0, 5.0, 100.0):
        assert control.update(t, True) == LevelDecision(True, LevelState.OFF, "", "", ())


def test_unknown_sensors_count_as_free_so_the_feeder_starts_feeding() -> None:
    decision = LevelControl(LevelSettings(LevelMode.ONE_SENSOR)).update(0.0, True)
    assert decision == LevelDecision(True, LevelState.FEEDING, "", "", (None,))
    decision = LevelControl(LevelSettings(LevelMode.TWO_SENSORS)).update(0.0, True)
    assert decision.sensors == (None, None)
    assert decision.feed_allowed


def test_parts_passing_the_sensor_never_pause_the_feeder() -> None:
    control = one_sensor(off=1.0)
    for k in range(40):  # a part every 0.5 s, each covering the sensor for 0.4 s
        t = 1.0 + 0.5 * k
        control.edge(t, FULL, True)
        assert state_at(control, t + 0.39) is LevelState.FEEDING
        control.edge(t + 0.4, FULL, False)
        assert state_at(control, t + 0.45) is LevelState.FEEDING


def test_sustained_cover_pauses_exactly_at_the_off_delay() -> None:
    control = one_sensor(off=0.3)
    control.edge(0.4, FULL, True)
    assert state_at(control, 0.699) is LevelState.FEEDING
    decision = control.update(0.7, True)  # 0.7 - 0.4 < 0.3 in floats: the slack counts it
    assert decision == LevelDecision(
        False, LevelState.FULL, "track full: sensor 1 covered for 0.3 s", "", (True,)
    )
    control = one_sensor(off=1.0)
    control.edge(2.0, FULL, True)
    assert state_at(control, 2.999) is LevelState.FEEDING
    assert control.update(3.0, True).reason == "track full: sensor 1 covered for 1.0 s"


def test_a_repeated_covered_edge_does_not_restart_the_off_delay() -> None:
    control = one_sensor(off=1.0)
    control.edge(1.0, FULL, True)
    control.edge(1.5, FULL, True)  # the same state again
    assert state_at(control, 2.0) is LevelState.FULL


def test_resume_after_the_sensor_is_free_for_the_on_delay_and_a_new_cover_restarts_it() -> None:
    control = one_sensor(off=1.0, on=0.5)
    control.edge(1.0, FULL, True)
    assert state_at(control, 2.0) is LevelState.FULL
    control.edge(5.0, FULL, False)
    assert state_at(control, 5.499, False) is LevelState.FULL
    decision = control.update(5.5, False)
    assert decision == LevelDecision(True, LevelState.FEEDING, "", "", (False,))
    control.edge(6.0, FULL, True)  # full again
    assert state_at(control, 7.0) is LevelState.FULL
    control.edge(8.0, FULL, False)
    control.edge(8.3, FULL, True)  # a part settles back: the free time starts again
    control.edge(8.4, FULL, False)
    assert state_at(control, 8.899) is LevelState.FULL
    assert state_at(control, 8.9) is LevelState.FEEDING


def test_two_sensors_pause_on_the_full_sensor_and_resume_only_when_the_low_one_is_free() -> None:
    """Refill: the queue covers the low sensor, feeding goes on; it reaches the full sensor: pause.
    Drain: the full sensor frees first, the pause holds until the low sensor is free on_delay_s."""
    control = two_sensors(off=1.0, on=1.0)
    control.edge(2.0, LOW, True)  # the queue reaches the low sensor
    assert state_at(control, 4.9) is LevelState.FEEDING  # covered for 2.9 s > off_delay_s
    control.edge(5.0, FULL, True)  # ... and the full sensor
    assert state_at(control, 5.999) is LevelState.FEEDING
    decision = control.update(6.0, True)
    assert (decision.state, decision.sensors) == (LevelState.FULL, (True, True))
    assert decision.reason == "track full: sensor 1 covered for 1.0 s"
    control.edge(8.0, FULL, False)  # parts picked: below the full sensor, above the low one
    for t in (9.0, 12.0, 19.999):
        assert state_at(control, t, False) is LevelState.FULL
    control.edge(20.0, LOW, False)
    assert state_at(control, 20.999, False) is LevelState.FULL
    decision = control.update(21.0, False)
    assert (decision.feed_allowed, decision.sensors) == (True, (False, False))
    # the same edges in one_sensor mode on the full sensor resume 1 s after it frees
    control = one_sensor(off=1.0, on=1.0)
    control.edge(5.0, FULL, True)
    assert state_at(control, 6.0) is LevelState.FULL
    control.edge(8.0, FULL, False)
    assert state_at(control, 9.0, False) is LevelState.FEEDING


def test_two_sensors_stay_paused_while_the_full_sensor_is_still_covered() -> None:
    """A part stuck at the full sensor: no resume into a full track (it would pause again at
    once); with the low sensor never seen, it resumes when the full one frees."""
    control = two_sensors(off=1.0, on=1.0)
    control.edge(1.0, LOW, True)
    control.edge(2.0, FULL, True)
    assert state_at(control, 3.0) is LevelState.FULL
    control.edge(4.0, LOW, False)
    assert state_at(control, 10.0, False) is LevelState.FULL
    control.edge(10.0, FULL, False)
    assert state_at(control, 10.0, False) is LevelState.FEEDING  # low free for 6 s already
    control = two_sensors(off=1.0, on=1.0)
    control.edge(2.0, FULL, True)
    assert control.update(3.0, True).sensors == (None, True)
    assert state_at(control, 9.0, False) is LevelState.FULL
    control.edge(9.5, FULL, False)
    assert state_at(control, 9.5, False) is LevelState.FEEDING


def test_sensor_time_out_latches_until_reset_and_restarts_from_it() -> None:
    control = one_sensor(timeout=5.0)
    assert state_at(control, 4.999) is LevelState.FEEDING
    reason = "sensor time-out: sensor 1 unchanged for 5.0 s while feeding"
    decision = control.update(5.0, True)
    assert decision == LevelDecision(False, LevelState.FAULT, reason, reason, (None,))
    control.edge(6.0, FULL, True)  # edges do not clear it
    control.edge(6.1, FULL, False)
    assert control.update(8.0, True) == LevelDecision(
        False, LevelState.FAULT, reason, reason, (False,)
    )
    control.reset(10.0)
    assert control.update(10.0, True) == LevelDecision(True, LevelState.FEEDING, "", "", (False,))
    assert state_at(control, 14.999) is LevelState.FEEDING
    assert state_at(control, 15.0) is LevelState.FAULT


def test_time_out_counts_feeding_time_only_and_each_change_restarts_it() -> None:
    control = one_sensor(off=1.0, on=1.0, timeout=5.0)
    assert state_at(control, 50.0, False) is LevelState.FEEDING  # drive not outputting
    assert state_at(control, 54.999) is LevelState.FEEDING  # feeding since 50 s
    control.edge(54.0, FULL, True)  # a part covers the sensor: a change
    control.edge(54.2, FULL, False)
    assert state_at(control, 59.1) is LevelState.FEEDING
    control.edge(59.0, FULL, True)  # the track fills up
    assert state_at(control, 60.0) is LevelState.FULL
    for t in (
        61.0,
        65.0,
        69.0,
        80.0,
        100.0,
    ):  # a long pause, covered: normal (even if reported feeding)
        assert state_at(control, t, t < 70.0) is LevelState.FULL
    control.edge(100.0, FULL, False)
    assert state_at(control, 101.0, False) is LevelState.FEEDING
    assert state_at(control, 101.5) is LevelState.FEEDING  # feeding restarts here
    assert state_at(control, 106.499) is LevelState.FEEDING
    assert state_at(control, 106.5) is LevelState.FAULT


def test_two_sensor_time_out_names_both_sensors_and_zero_disables_it() -> None:
    control = two_sensors(timeout=30.0)
    assert control.update(30.0, True).fault == (
        "sensor time-out: low sensor 0 and full sensor 1 unchanged for 30.0 s while feeding"
    )
    control = two_sensors(timeout=0.0)
    assert state_at(control, 1e6) is LevelState.FEEDING


def test_reset_while_paused_keeps_the_pause_and_restarts_the_on_delay() -> None:
    control = one_sensor(off=1.0, on=2.0)
    control.edge(1.0, FULL, True)
    assert state_at(control, 2.0) is LevelState.FULL
    control.edge(3.0, FULL, False)
    control.reset(4.0)
    assert state_at(control, 5.999, False) is LevelState.FULL  # free for 2 s, but reset at 4 s
    assert state_at(control, 6.0, False) is LevelState.FEEDING


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"off_delay_s": math.nan}, "level.off_delay_s=nan must be finite and >= 0"),
        ({"on_delay_s": math.inf}, "level.on_delay_s=inf must be finite and >= 0"),
        ({"off_delay_s": -1.0}, "level.off_delay_s=-1.0 must be finite and >= 0"),
        ({"sensor_timeout_s": -0.5}, "level.sensor_timeout_s=-0.5 must be finite and >= 0"),
        ({"sensor_timeout_s": "30"}, "level.sensor_timeout_s='30' must be a number of seconds"),
        ({"full_sensor_index": True}, "level.full_sensor_index=True must be an integer >= 0"),
        ({"low_sensor_index": -1}, "level.low_sensor_index=-1 must be an integer >= 0"),
        ({"full_sensor_index": 1.0}, "level.full_sensor_index=1.0 must be an integer >= 0"),
        ({"low_sensor_index": 1}, "level.low_sensor_index=1 equals level.full_sensor_index"),
        ({"mode": "three"}, "level.mode='three' is not a level mode"),
    ],
)
def test_bad_settings_are_refused_naming_the_value(
    changes: dict[str, object], message: str
) -> None:
    values: dict[str, object] = {
        "mode": "two_sensors",
        "full_sensor_index": 1,
        "low_sensor_index": 0,
        "off_delay_s": 1.0,
        "on_delay_s": 1.0,
        "sensor_timeout_s": 30.0,
    }
    values.update(changes)
    with pytest.raises(LevelError) as raised:
        LevelSettings.from_values(**values)  # type: ignore[arg-type]
    assert str(raised.value).startswith(message)


def test_from_values_takes_the_parameter_values() -> None:
    settings = LevelSettings.from_values(" One_Sensor ", 2, 2, 1, 0.5, 0)
    assert settings == LevelSettings(LevelMode.ONE_SENSOR, 2, 2, 1.0, 0.5, 0.0)
    assert isinstance(settings.off_delay_s, float)
    assert settings.watched == (2,)  # one sensor: equal indices are fine, the low one is unused
    with pytest.raises(LevelError) as raised:
        LevelSettings.from_values("minmax", 1, 0, 1.0, 1.0, 30.0)
    assert str(raised.value) == (
        "level.mode='minmax' is not a level mode (valid: 'off', 'one_sensor', 'two_sensors')"
    )


def test_sensor_indices_are_checked_against_the_feeder() -> None:
    with pytest.raises(LevelError) as raised:
        LevelSettings(LevelMode.ONE_SENSOR, full_sensor_index=5).check_sensor_count(2)
    assert str(raised.value) == (
        "level.full_sensor_index=5: the feeder has 2 part-present sensors (0..1)"
    )
    two = LevelSettings(LevelMode.TWO_SENSORS, full_sensor_index=0, low_sensor_index=1)
    with pytest.raises(LevelError, match=r"^level\.low_sensor_index=1: .* 1 part-present sensor "):
        two.check_sensor_count(1)
    with pytest.raises(LevelError, match="no part-present sensors"):
        LevelSettings(LevelMode.ONE_SENSOR, full_sensor_index=0).check_sensor_count(0)
    two.check_sensor_count(2)
    LevelSettings(full_sensor_index=9).check_sensor_count(0)  # off: no sensor used


def test_non_finite_times_are_refused() -> None:
    control = one_sensor()
    for call in (
        lambda: control.edge(math.nan, FULL, True),
        lambda: control.update(math.inf, True),
        lambda: control.reset(-math.inf),
    ):
        with pytest.raises(LevelError, match=r"^t_s=.* must be finite$"):
            call()


def test_a_late_edge_counts_from_its_stamp_and_a_stale_one_is_dropped() -> None:
    control = one_sensor(off=1.0)
    assert state_at(control, 10.0) is LevelState.FEEDING
    control.edge(9.97, FULL, True)  # stamped 30 ms before the last tick
    assert state_at(control, 10.969) is LevelState.FEEDING
    assert state_at(control, 10.97) is LevelState.FULL
    # a passing part whose rising edge arrives after its falling one: not left covered
    control = one_sensor(off=1.0)
    control.edge(5.02, FULL, False)
    control.edge(5.00, FULL, True)
    assert control.stale_edges == 1
    decision = control.update(20.0, True)
    assert (decision.state, decision.sensors) == (LevelState.FEEDING, (False,))
    control.edge(21.0, LOW, True)  # not watched in one_sensor mode
    assert control.update(30.0, True).sensors == (False,)


def test_time_never_runs_back_but_a_clock_restart_restarts_the_timers() -> None:
    control = one_sensor(off=1.0)
    control.edge(1.0, FULL, True)
    assert state_at(control, 1.5) is LevelState.FEEDING
    assert state_at(control, 1.45) is LevelState.FEEDING  # a small step back: still 1.5 s
    assert state_at(control, 1.999) is LevelState.FEEDING
    assert state_at(control, 2.0) is LevelState.FULL
    control = one_sensor(off=1.0)
    control.edge(10.0, FULL, True)
    assert state_at(control, 10.5) is LevelState.FEEDING
    assert state_at(control, 0.0) is LevelState.FEEDING  # sim time restarted: state kept
    assert state_at(control, 0.999) is LevelState.FEEDING
    assert state_at(control, 1.0) is LevelState.FULL
    control.edge(1.2, FULL, False)  # the new clock's stamps are not stale
    assert state_at(control, 2.2, False) is LevelState.FEEDING
    assert control.stale_edges == 0


def test_a_seeded_state_counts_from_the_first_update_not_from_its_old_stamp() -> None:
    control = LevelControl(LevelSettings(LevelMode.ONE_SENSOR, FULL, LOW, 1.0, 1.0, 0.0))
    control.edge(5.0, FULL, True)  # the node seeds the last known state at its stamp
    assert state_at(control, 100.0) is LevelState.FEEDING
    assert state_at(control, 100.999) is LevelState.FEEDING
    assert state_at(control, 101.0) is LevelState.FULL


def test_an_edge_stamped_on_the_clock_before_a_restart_does_not_block_the_new_one() -> None:
    control = one_sensor(off=1.0, on=1.0)
    assert state_at(control, 10.5) is LevelState.FEEDING
    assert state_at(control, 0.0) is LevelState.FEEDING  # sim time restarted
    control.edge(10.6, FULL, True)  # in flight from the old clock
    assert state_at(control, 0.1) is LevelState.FEEDING  # its stamp is taken as now
    assert state_at(control, 1.1) is LevelState.FULL
    control.edge(1.5, FULL, False)  # the new clock: not stale
    assert state_at(control, 2.5, False) is LevelState.FEEDING
    assert control.stale_edges == 0


@pytest.mark.parametrize("leaves_first", [True, False])
def test_touching_parts_changing_over_at_one_instant_leave_the_sensor_covered(
    leaves_first: bool,
) -> None:
    """One part leaves the full sensor as the next arrives, at one stamp, in either order: the
    barrier stays dark, so the off delay runs on from the first part's arrival."""
    control = one_sensor(off=2.0, timeout=3.0)
    control.edge(1.0, FULL, True)
    for present in (False, True) if leaves_first else (True, False):
        control.edge(2.5, FULL, present)  # covered, then the second edge at the same instant
    if not leaves_first:  # covered -> covered is no change; then the leaving edge comes
        control.edge(2.5, FULL, True)
    assert state_at(control, 3.0) is LevelState.FULL  # 2 s since 1.0, not since 2.5
    # a real free instant (0.1 s) does restart the delay
    fresh = one_sensor(off=2.0)
    fresh.edge(1.0, FULL, True)
    fresh.edge(2.5, FULL, False)
    fresh.edge(2.6, FULL, True)
    assert state_at(fresh, 3.0) is LevelState.FEEDING
    assert state_at(fresh, 4.6) is LevelState.FULL
