"""ROS time as float seconds: the one conversion every node uses."""

from __future__ import annotations

import time

import pytest
from builtin_interfaces.msg import Time
from rclpy.clock import Clock, ClockType

from feeder_ros.nodes.ros_time import clock_seconds, stamp_seconds


def test_a_stamp_keeps_its_microseconds_at_todays_epoch() -> None:
    assert stamp_seconds(Time(sec=1_795_790_307, nanosec=581_555_800)) == pytest.approx(
        1_795_790_307.5815558, abs=1e-6
    )
    assert stamp_seconds(Time(sec=0, nanosec=999_999_999)) == pytest.approx(0.999999999)
    assert stamp_seconds(Time()) == 0.0


def test_a_clock_reads_in_seconds() -> None:
    steady = Clock(clock_type=ClockType.STEADY_TIME)  # CLOCK_MONOTONIC, as time.monotonic
    before = time.monotonic()
    now = clock_seconds(steady)
    after = time.monotonic()
    assert before - 0.01 <= now <= after + 0.01
