"""StallDetector: a timer tick that comes late means the process stalled."""

from __future__ import annotations

import math

import pytest

from feeder_ros.monitoring.speed_monitor import Alarm, MonitorConfig, SpeedMonitor
from feeder_ros.nodes.stall_detector import MIDDLEWARE_CATCH_UP_S, StallDetector


def test_on_time_ticks_are_no_stall() -> None:
    detector = StallDetector(0.5)  # late: more than 1.0 s after the last tick
    assert [detector.stalled(t) for t in (10.0, 10.5, 11.0, 12.0, 12.6)] == [False] * 5
    assert detector.stalls == 0


def test_a_late_tick_is_a_stall_and_the_next_one_is_not() -> None:
    detector = StallDetector(0.5)
    assert not detector.stalled(10.0)
    assert detector.stalled(12.6)  # not running for about 2.1 s
    assert not detector.stalled(13.1)
    assert detector.stalls == 1
    assert detector.last_stall_s == pytest.approx(2.6)  # the gap between the ticks
    assert detector.stalled(17.0)  # a later, longer stall replaces it
    assert detector.last_stall_s == pytest.approx(3.9)
    assert detector.diagnostic_values() == {"stalls_seen": "2", "last_stall_s": "3.900"}


def test_a_stall_before_the_first_tick_counts_from_the_timer_s_start() -> None:
    # a node compiling a kernel right after start-up: its first tick comes 2.6 s late
    assert StallDetector(0.5, start_s=10.0).stalled(12.6)
    assert not StallDetector(0.5, start_s=10.0).stalled(10.5)
    assert not StallDetector(0.5).stalled(12.6)  # no start given: the first tick is never late


def test_a_node_starved_for_good_judges_every_other_tick() -> None:
    detector = StallDetector(0.5)
    ticks = [detector.stalled(10.0 + 3.0 * k) for k in range(6)]  # every tick 3 s late
    assert ticks == [False, True, False, True, False, True]
    assert detector.stalls == 3


@pytest.mark.parametrize(
    ("period", "slack", "text"),
    [
        (0.0, 0.5, "period_s=0.0"),
        (math.nan, 0.5, "period_s=nan"),
        (0.5, -1.0, "slack_s=-1.0"),
        (0.5, math.inf, "slack_s=inf"),
    ],
)
def test_bad_periods_are_refused(period: float, slack: float, text: str) -> None:
    with pytest.raises(ValueError, match=text):
        StallDetector(period, slack)


@pytest.mark.parametrize("catch_up", [-1.0, math.nan, math.inf])
def test_a_bad_catch_up_is_refused(catch_up: float) -> None:
    with pytest.raises(ValueError, match=f"catch_up_s={catch_up!r}"):
        StallDetector(0.5, catch_up_s=catch_up)


def test_the_catch_up_follows_a_reported_stall_on_the_same_clock() -> None:
    detector = StallDetector(0.5, catch_up_s=3.0)
    ticks = (10.0, 10.5, 13.1, 13.6, 14.1, 15.1, 15.6, 16.1, 16.6)  # stalled before 13.1
    assert [detector.resuming(t) for t in ticks] == [False, False] + [True] * 5 + [False] * 2
    assert detector.stalls == 1
    assert StallDetector(0.5).catch_up_s == MIDDLEWARE_CATCH_UP_S


def test_with_a_faster_node_clock_the_catch_up_still_lasts_its_wall_seconds() -> None:
    """How the speed monitor node uses it under a simulation's /clock at 10x real time: the
    process stalls for 2.1 s of wall time (21 s of node time) and the estimates sent meanwhile
    reach it 2.5 s (wall) after it resumed. The catch-up, counted on the wall clock, spans 30 s
    of node time: no sensor timeout. Granting the catch-up on the node clock (3 s of it, 0.3 s
    of wall time) raised one."""
    config = MonitorConfig(sensor_timeout_s=2.0, starvation_time_s=1000.0)  # no parts here

    def run(catch_up_s: float) -> list[int]:
        monitor = SpeedMonitor(config)
        detector = StallDetector(0.1, catch_up_s=catch_up_s)
        monitor.on_drive(0.0, True, 0.02)
        alarms = []
        wall_ticks = [0.1 * k for k in range(11)] + [3.1 + 0.1 * k for k in range(60)]
        for wall in wall_ticks:
            node = 10.0 * wall
            if wall <= 1.0 or wall >= 5.6:  # estimates: before the stall, and once caught up
                monitor.on_estimate(node, 0.02, 1.0)
            if detector.resuming(wall):
                monitor.resumed(node)
            alarms.append(monitor.evaluate(node).alarms)
        return alarms

    assert [a for a in run(3.0) if a] == []
    raised = [a for a in run(0.3) if a]  # 3 s of node time: the catch-up on the node clock
    assert raised
    assert all(a == Alarm.SENSOR_TIMEOUT for a in raised)
