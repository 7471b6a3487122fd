"""The estimator's health for /diagnostics, without ROS (estimator_records.input_health)."""

from __future__ import annotations

from feeder_ros.estimation.estimator_records import Status, input_health


def test_input_health_waits_then_times_out_and_warns_on_unusable_estimates() -> None:
    timeouts = (10.0, 1.0)  # start-up, input
    assert input_health(0, 3.0, 3.0, *timeouts, Status.NO_INPUT, "") == (
        1,
        "waiting for the first accelerometer sample (3.0 s since start)",
    )
    assert input_health(0, 12.0, 12.0, *timeouts, Status.NO_INPUT, "") == (
        2,
        "no accelerometer sample in 12.0 s since start",
    )
    assert input_health(50, 1.5, 9.0, *timeouts, Status.OK, "") == (
        2,
        "sensor timeout: no accelerometer sample for 1.5 s",
    )
    assert input_health(50, 0.1, 9.0, *timeouts, Status.SETTLING, "settling: 0.4 s left") == (
        1,
        "settling: 0.4 s left",
    )
    assert input_health(50, 0.1, 9.0, *timeouts, Status.GAP, "") == (1, "GAP")
    assert input_health(50, 0.1, 9.0, *timeouts, Status.OK, "") == (0, "estimating")
