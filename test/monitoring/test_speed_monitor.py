"""The speed monitor's pure core: measurements, alarms with hysteresis, time jumps, refusals."""

from __future__ import annotations

import math
import re

import pytest

from feeder_ros.monitoring.speed_monitor import Alarm, MonitorConfig, MonitorStatus, SpeedMonitor
from feeder_ros.physics.parameters import ParameterError

TARGET = 0.02


def _run(
    monitor: SpeedMonitor, t0: float, t1: float, speed: float, dt: float = 0.1
) -> MonitorStatus:
    status = monitor.evaluate(t0)
    t = t0
    while t <= t1 + 1e-9:
        monitor.on_estimate(t, speed, 1.0)
        status = monitor.evaluate(t)
        t += dt
    return status


def test_underspeed_raises_after_the_delay_and_clears_with_hysteresis() -> None:
    monitor = SpeedMonitor(MonitorConfig(speed_tolerance=0.15, clear_ratio=0.6, alarm_delay_s=2.0))
    monitor.on_drive(0.0, True, TARGET)
    assert _run(monitor, 0.0, 5.0, TARGET).alarms == 0
    status = _run(monitor, 5.1, 6.5, 0.8 * TARGET)  # 20 % slow for 1.4 s: not yet
    assert status.alarms == 0
    status = _run(monitor, 6.6, 7.5, 0.8 * TARGET)  # ... for 2.4 s: raised
    assert status.alarms == Alarm.UNDERSPEED
    assert status.level == 1
    assert status.message == "underspeed"
    assert status.details["speed_error_percent"] == "-20.0"
    # 12 % slow: inside the tolerance but not below the clear level (9 %): stays raised
    assert _run(monitor, 7.6, 12.0, 0.88 * TARGET).alarms == Alarm.UNDERSPEED
    assert _run(monitor, 12.1, 12.5, 0.95 * TARGET).alarms == 0


def test_overspeed() -> None:
    monitor = SpeedMonitor()
    monitor.on_drive(0.0, True, TARGET)
    assert _run(monitor, 0.0, 3.0, 1.5 * TARGET).alarms == Alarm.OVERSPEED


def test_stall_is_an_error_and_clears_when_parts_move() -> None:
    monitor = SpeedMonitor(MonitorConfig(stall_time_s=3.0, starvation_time_s=100.0))
    monitor.on_drive(0.0, True, math.nan)
    assert _run(monitor, 0.0, 2.5, 0.0).alarms == 0
    status = _run(monitor, 2.6, 3.5, 1e-5)
    assert status.alarms & Alarm.STALL
    assert status.level == 2
    assert _run(monitor, 3.6, 4.0, 0.01).alarms == 0


def test_no_alarm_while_idle() -> None:
    monitor = SpeedMonitor()
    monitor.on_drive(0.0, False, TARGET)
    status = _run(monitor, 0.0, 100.0, 0.0)
    assert status.alarms == 0
    assert status.message == "idle"


def test_starvation_raises_without_parts_and_clears_on_the_next_part() -> None:
    monitor = SpeedMonitor(MonitorConfig(starvation_time_s=10.0))
    monitor.on_drive(0.0, True, math.nan)
    assert _run(monitor, 0.0, 9.5, 0.01).alarms == 0
    assert _run(monitor, 9.6, 10.5, 0.01).alarms == Alarm.STARVATION
    monitor.on_sensor_edge(10.6, 0, 7, True)
    assert monitor.evaluate(10.7).alarms == 0


def test_track_full_when_a_sensor_stays_covered() -> None:
    monitor = SpeedMonitor(MonitorConfig(track_full_time_s=5.0))
    monitor.on_drive(0.0, True, math.nan)
    monitor.on_sensor_edge(1.0, 1, 4, True)
    assert not _run(monitor, 1.0, 5.9, 0.01).alarms & Alarm.TRACK_FULL
    status = _run(monitor, 6.0, 6.5, 0.01)
    assert status.alarms & Alarm.TRACK_FULL
    assert status.level == 2
    monitor.on_sensor_edge(6.6, 1, 4, False)
    assert not monitor.evaluate(6.7).alarms & Alarm.TRACK_FULL


def test_sensor_timeout_when_estimates_stop() -> None:
    monitor = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0, min_confidence=0.5))
    monitor.on_drive(0.0, True, math.nan)
    _run(monitor, 0.0, 3.0, 0.01)
    assert monitor.evaluate(4.0).alarms == 0
    status = monitor.evaluate(5.5)
    assert status.alarms == Alarm.SENSOR_TIMEOUT
    assert math.isnan(status.estimated_speed_mps)
    # an estimate below min_confidence gives no speed, but the estimator is alive: a warning,
    # not a sensor timeout
    monitor.on_estimate(5.6, 0.01, 0.1)
    status = monitor.evaluate(5.7)
    assert (status.level, status.alarms) == (1, 0)
    assert status.message == "no confident speed estimate for 2.7 s (confidence 0.10 < 0.50)"
    assert math.isnan(status.estimated_speed_mps)
    # silent again for sensor_timeout_s: the timeout is back
    assert monitor.evaluate(7.5).alarms == 0
    assert monitor.evaluate(7.7).alarms == Alarm.SENSOR_TIMEOUT


def test_start_up_is_waited_for_and_a_live_estimator_gone_silent_is_a_timeout() -> None:
    """Before the first estimate message the monitor says it waits (WARN), for up to
    startup_timeout_s after the drive started; only then, or when a live stream stops, ERROR."""
    monitor = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0, startup_timeout_s=10.0))
    monitor.on_drive(0.0, True, TARGET)
    status = monitor.evaluate(4.3)
    assert (status.level, status.alarms) == (1, 0)
    assert status.message == "waiting for the first speed estimate (4.3 s since the start)"
    assert monitor.evaluate(10.0).alarms == 0
    status = monitor.evaluate(10.2)
    assert (status.level, status.alarms) == (2, Alarm.SENSOR_TIMEOUT)
    # a stream that was live and went silent: the sensor timeout after sensor_timeout_s
    live = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0, startup_timeout_s=10.0))
    live.on_drive(0.0, True, TARGET)
    _run(live, 0.0, 1.0, TARGET)
    assert live.evaluate(3.0).alarms == 0
    assert live.evaluate(3.2).alarms == Alarm.SENSOR_TIMEOUT
    # also when the drive stopped meanwhile (e.g. it faulted: the simulator died)
    live.on_drive(3.3, False, math.nan)
    status = live.evaluate(3.4)
    assert (status.level, status.alarms) == (2, Alarm.SENSOR_TIMEOUT)
    # an idle monitor that never heard an estimate waits without an alarm
    idle = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0, startup_timeout_s=10.0))
    assert idle.evaluate(30.0).alarms == 0


def test_the_monitors_own_stall_is_not_the_inputs_silence() -> None:
    """Not listening from 3.0 to 5.6 s (the process stalled), then the middleware's catch-up
    until 6.6 s (the node calls resumed at each tick in it): silence counts from 6.6 s, for the
    estimates, parts and covered sensors alike."""
    config = MonitorConfig(sensor_timeout_s=2.0, starvation_time_s=4.0, track_full_time_s=4.0)
    monitor = SpeedMonitor(config)
    monitor.on_drive(0.0, True, TARGET)
    monitor.on_sensor_edge(0.0, 0, 1, True)  # the last part seen; its sensor stays covered
    assert _run(monitor, 0.0, 3.0, TARGET).message == "at target (20.00 +- 0.00 mm/s)"
    for t in (5.6, 6.0, 6.6, 8.0, 8.6):
        if t <= 6.6:
            monitor.resumed(t)
        status = monitor.evaluate(t)
        assert (status.level, status.alarms) == (0, 0), (t, status.message)
        assert status.message == "waiting for a speed estimate"  # the speed is too old to use
    # 2 s from 6.6 s without an estimate: a sensor timeout; 4 s without a part: starvation;
    # the first sensor covered for 4 s of listening: track full
    assert monitor.evaluate(8.7).alarms == Alarm.SENSOR_TIMEOUT
    assert monitor.evaluate(10.5).alarms == Alarm.SENSOR_TIMEOUT
    all_three = Alarm.SENSOR_TIMEOUT | Alarm.STARVATION | Alarm.TRACK_FULL
    assert monitor.evaluate(10.6).alarms == all_three
    # the same silence without a stall raised all three long ago
    again = SpeedMonitor(config)
    again.on_drive(0.0, True, TARGET)
    again.on_sensor_edge(0.0, 0, 1, True)
    _run(again, 0.0, 3.0, TARGET)
    assert again.evaluate(5.6).alarms == all_three


def test_an_estimator_settling_after_a_start_is_a_warning_not_a_sensor_timeout() -> None:
    """After a (re)start the estimator keeps publishing, below min_confidence while its window
    still holds the ramp: the monitor warns that it has no speed to check, raises no alarm, and
    is at target again once an estimate is sure enough."""
    monitor = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0, min_confidence=0.5))
    monitor.on_drive(0.0, True, TARGET)
    levels = []
    for i in range(40):
        t = i / 10
        monitor.on_estimate(t, 0.3 * TARGET, 0.2)
        status = monitor.evaluate(t)
        levels.append((t, status.level, status.alarms))
    assert all(alarms == 0 for _, _, alarms in levels)
    assert {level for t, level, _ in levels if t <= 2.0} == {0}
    assert {level for t, level, _ in levels if t >= 2.1} == {1}
    assert status.message == "no confident speed estimate for 3.9 s (confidence 0.20 < 0.50)"
    monitor.on_estimate(4.0, math.nan, 0.9)  # sure of nothing: still no speed
    assert monitor.evaluate(4.0).message == "no confident speed estimate for 4.0 s (no speed in it)"
    status = _run(monitor, 4.1, 4.5, TARGET)
    assert (status.level, status.alarms, status.message) == (0, 0, "at target (20.00 +- 0.00 mm/s)")


def test_transit_speed_by_part_id_and_first_in_first_out() -> None:
    monitor = SpeedMonitor(MonitorConfig(transit_distance_m=0.085))
    monitor.on_sensor_edge(10.0, 0, 3, True)
    monitor.on_sensor_edge(11.0, 0, 4, True)
    monitor.on_sensor_edge(15.0, 1, 3, True)
    assert monitor.evaluate(15.0).transit_speed_mps == pytest.approx(0.085 / 5.0)
    anonymous = SpeedMonitor(MonitorConfig(transit_distance_m=0.085))
    anonymous.on_sensor_edge(1.0, 0, None, True)
    anonymous.on_sensor_edge(2.0, 0, None, True)
    anonymous.on_sensor_edge(5.25, 1, None, True)  # the first part in is the first out
    assert anonymous.evaluate(5.3).transit_speed_mps == pytest.approx(0.085 / 4.25)


def test_transit_is_timed_by_the_edge_stamps_not_by_delivery() -> None:
    monitor = SpeedMonitor(MonitorConfig(transit_distance_m=0.085))
    monitor.on_sensor_edge(20.0, 0, 1, True, edge_t=10.0)  # delivered late, in a burst
    monitor.on_sensor_edge(20.1, 1, 1, True, edge_t=15.0)
    assert monitor.evaluate(20.2).transit_speed_mps == pytest.approx(0.085 / 5.0)


def test_feed_rate_over_the_window() -> None:
    monitor = SpeedMonitor(MonitorConfig(feed_window_s=60.0))
    monitor.on_drive(0.0, True, math.nan)
    for k in range(6):
        monitor.on_exit(5.0 * (k + 1))
    assert monitor.evaluate(30.0).feed_rate_ppm == pytest.approx(12.0)  # 6 parts in 30 s
    assert monitor.evaluate(60.0).feed_rate_ppm == pytest.approx(6.0)
    assert monitor.evaluate(100.0).feed_rate_ppm == pytest.approx(0.0)  # all left the window


def test_feed_rate_right_after_a_restart_counts_only_the_new_run() -> None:
    """The window shrinks to the time since the drive started: exits from before the restart
    are not divided by those few milliseconds (30,000 parts/min for a moment)."""
    monitor = SpeedMonitor(MonitorConfig(feed_window_s=60.0))
    monitor.on_drive(0.0, True, math.nan)
    for k in range(5):
        monitor.on_exit(2.0 * (k + 1))
    monitor.on_drive(10.5, False, math.nan)
    monitor.on_drive(12.0, True, math.nan)
    assert monitor.evaluate(12.01).feed_rate_ppm == 0.0
    monitor.on_exit(13.0)
    assert monitor.evaluate(14.0).feed_rate_ppm == pytest.approx(60.0 / 2.0)  # 1 part in 2 s
    assert monitor.evaluate(72.0).feed_rate_ppm == pytest.approx(1.0)  # full window: 1 in 60 s


def test_time_jumping_back_restarts_the_windows() -> None:
    monitor = SpeedMonitor()
    monitor.on_drive(100.0, True, TARGET)
    monitor.on_exit(101.0)
    _run(monitor, 101.0, 110.0, 0.5 * TARGET)
    assert monitor.evaluate(110.0).alarms == Alarm.UNDERSPEED
    status = monitor.evaluate(5.0)  # e.g. a bag replayed again
    assert status.alarms == 0
    assert status.feed_rate_ppm == 0.0
    assert status.details["time_jumps_back"] == "1"


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"speed_tolerance": 0.0}, "speed_tolerance=0.0"),
        ({"stall_time_s": math.nan}, "stall_time_s=nan"),
        ({"clear_ratio": 1.5}, "clear_ratio=1.5"),
        ({"transit_pair": (1, 1)}, "transit_pair=(1, 1)"),
    ],
)
def test_bad_configuration_is_refused_with_the_value(
    change: dict[str, object], needle: str
) -> None:
    with pytest.raises(ParameterError, match=re.escape(needle)):
        MonitorConfig(**change)


def test_non_finite_time_is_refused() -> None:
    with pytest.raises(ParameterError, match="time nan"):
        SpeedMonitor().evaluate(math.nan)


def test_an_infinite_target_is_refused_and_changes_nothing() -> None:
    monitor = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0))
    with pytest.raises(ParameterError, match="target_speed_mps=inf"):
        monitor.on_drive(1.0, True, math.inf)
    # still idle: no driving since 1.0, so no alarm for the missing estimates
    status = monitor.evaluate(10.0)
    assert (status.level, status.alarms) == (0, 0), status


def test_no_at_target_before_an_estimate_says_so() -> None:
    monitor = SpeedMonitor(MonitorConfig(sensor_timeout_s=2.0))
    monitor.on_drive(0.0, True, TARGET)
    status = monitor.evaluate(1.0)  # driving, no estimate yet: not "at target"
    assert (status.level, status.alarms, status.message) == (0, 0, "waiting for a speed estimate")
    assert _run(monitor, 1.1, 1.5, TARGET).message == "at target (20.00 +- 0.00 mm/s)"
    assert monitor.evaluate(4.0).alarms == Alarm.SENSOR_TIMEOUT  # estimates stopped


def test_new_limits_keep_the_raised_alarms_and_the_history() -> None:
    monitor = SpeedMonitor(MonitorConfig(speed_tolerance=0.15, alarm_delay_s=2.0, stall_time_s=3.0))
    monitor.on_drive(0.0, True, TARGET)
    for t in (0.5, 1.0, 1.5):
        monitor.on_exit(t)
    status = _run(monitor, 2.0, 6.0, 0.0)  # driving, parts not moving: a stall
    assert status.alarms & Alarm.STALL
    assert status.level == 2
    monitor.reconfigure(MonitorConfig(speed_tolerance=0.3, alarm_delay_s=2.0, stall_time_s=3.0))
    again = monitor.evaluate(6.05)
    assert again.alarms & Alarm.STALL  # still raised: the stall timer was kept
    assert again.feed_rate_ppm == pytest.approx(3 * 60.0 / 6.05)  # the 3 exits still counted
    assert again.target_speed_mps == TARGET
    assert monitor.config.speed_tolerance == 0.3


def test_speed_is_judged_against_the_estimate_s_interval() -> None:
    """At target only when the whole 95 % interval lies within the tolerance; an alarm only when
    the whole interval lies beyond it; in between, a warning that the target is not confirmed."""
    monitor = SpeedMonitor(MonitorConfig(speed_tolerance=0.15, alarm_delay_s=1.0))
    monitor.on_drive(0.0, True, TARGET)

    def judged(t: float, speed: float, sigma: float) -> MonitorStatus:
        status = monitor.evaluate(t)
        for k in range(15):
            monitor.on_estimate(t + 0.1 * k, speed, 0.9, sigma)
            status = monitor.evaluate(t + 0.1 * k)
        return status

    # 20.4 +- 2 * 0.5 mm/s lies within 20 +- 3 mm/s: at target
    status = judged(1.0, 0.0204, 0.0005)
    assert (status.level, status.alarms) == (0, 0)
    assert status.message == "at target (20.40 +- 1.00 mm/s)"
    assert status.estimated_speed_uncertainty_mps == 0.0005
    # the same speed, uncalibrated (+- 8 mm/s): not confirmed, and no alarm either
    status = judged(3.0, 0.0204, 0.004)
    assert (status.level, status.alarms) == (1, 0)
    assert status.message == (
        "the estimate cannot confirm the target: 20.40 +- 8.00 mm/s against 20.00 mm/s +- 15 %: "
        "its interval is wider than the tolerance (part model not calibrated yet?)"
    )
    # 15 mm/s, 25 % slow, but +- 4 mm/s reaches into the tolerance: no underspeed alarm
    assert judged(5.0, 0.015, 0.002).alarms == 0
    # 15 +- 2.4 mm/s: narrower than the tolerance, straddling its edge
    status = judged(6.5, 0.015, 0.0012)
    assert status.alarms == 0
    assert status.message.endswith(": its interval reaches beyond the tolerance")
    # 15 +- 0.4 mm/s lies wholly below 17 mm/s: said at once, underspeed after the delay
    monitor.on_estimate(8.0, 0.015, 0.9, 0.0002)
    status = monitor.evaluate(8.0)
    assert (status.level, status.alarms) == (1, 0)
    assert status.message.endswith(
        "15.00 +- 0.40 mm/s against 20.00 mm/s +- 15 %: the part speed is off target "
        "(starting, ramping, or an alarm after its delay)"
    )
    assert judged(8.5, 0.015, 0.0002).alarms == Alarm.UNDERSPEED
    # a part at rest reads 0.00, not "-0.00" (an estimate a hair below zero)
    resting = SpeedMonitor(MonitorConfig(speed_tolerance=0.15, alarm_delay_s=1.0))
    resting.on_drive(0.0, True, TARGET)
    resting.on_estimate(0.5, -1e-7, 0.9, 1e-7)
    assert "cannot confirm the target: 0.00 +- 0.00 mm/s against" in resting.evaluate(0.5).message
    # an estimate without a finite uncertainty gives no speed
    monitor.on_estimate(11.0, 0.02, 1.0, math.nan)
    assert math.isnan(monitor.evaluate(11.0 + 2.5).estimated_speed_mps)
