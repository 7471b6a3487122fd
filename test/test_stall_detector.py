"""StallDetector: a timer tick that comes late means the process stalled."""

from __future__ import annotations

import math

import pytest

from feeder_ros.nodes.stall_detector import StallDetector


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
