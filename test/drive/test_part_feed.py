"""The feed_parts action's core, driven with explicit times (no ROS, no clock)."""

from __future__ import annotations

import math

import pytest

from feeder_ros.drive.part_feed import (
    PART_ID_UNKNOWN,
    FeedMode,
    FeedOutcome,
    FeedRequest,
    PartFeed,
    request_refusal,
)


def count_feed(n: int, sensor: int = 1, timeout_s: float = 20.0, t0: float = 100.0) -> PartFeed:
    return PartFeed(FeedRequest(FeedMode.COUNT, n, sensor, timeout_s), t0)


def until_feed(covered: bool | None = None, timeout_s: float = 20.0) -> PartFeed:
    return PartFeed(FeedRequest(FeedMode.UNTIL_PRESENT, 0, 1, timeout_s), 100.0, covered)


def pass_part(feed: PartFeed, t: float, part_id: int, sensor: int = 1) -> None:
    feed.edge(t, sensor, part_id, True)
    feed.edge(t + 0.1, sensor, part_id, False)


def test_count_is_exact_on_falling_edges_and_ignores_other_sensors_and_late_edges() -> None:
    feed = count_feed(3)
    feed.edge(101.0, 1, 7, True)  # arrived, not yet passed
    feed.edge(101.0, 0, 8, False)  # another sensor
    assert feed.update(101.5, True).delivered == 0
    pass_part(feed, 102.0, 9)
    pass_part(feed, 103.0, 10)
    progress = feed.update(103.5, True)
    assert (progress.delivered, progress.done, progress.outcome) == (2, False, None)
    pass_part(feed, 104.0, 11)
    assert feed.done
    pass_part(feed, 105.0, 12)  # after done: ignored
    final = feed.update(110.0, True)
    assert final.delivered == 3
    assert final.outcome is FeedOutcome.SUCCEEDED
    assert final.elapsed_s == pytest.approx(4.1)  # ends at the third falling edge, not at update
    assert final.last_delivery_s == pytest.approx(104.1)
    assert final.time_per_part_s == pytest.approx(4.1 / 3)
    assert final.reason == "delivered 3 parts in 4.1 s"


def test_a_known_id_counts_once_and_unknown_ids_each_count() -> None:
    feed = count_feed(3)
    for t in (101.0, 101.2, 101.4):
        feed.edge(t, 1, 42, False)  # the same part's falling edge repeated
    assert feed.update(102.0, True).delivered == 1
    feed.edge(103.0, 1, PART_ID_UNKNOWN, False)
    feed.edge(103.0, 1, PART_ID_UNKNOWN, False)  # a real sensor: two parts
    assert feed.done
    assert feed.update(104.0, True).delivered == 3


def test_edges_stamped_before_the_goal_are_ignored() -> None:
    feed = count_feed(1)
    feed.edge(99.9, 1, 5, False)
    assert not feed.done
    feed.edge(100.0, 1, 5, False)  # at the start: counts (the id was not recorded before)
    assert feed.done
    assert feed.update(100.0, False).delivered == 1


def test_until_present_ends_on_the_rising_edge() -> None:
    feed = until_feed(covered=False)
    feed.edge(101.0, 1, 3, False)  # a falling edge is not a part at the pick position
    feed.edge(101.0, 0, 3, True)  # another sensor
    assert not feed.update(101.5, True).done
    feed.edge(102.5, 1, PART_ID_UNKNOWN, True)
    final = feed.update(103.0, True)
    assert (final.outcome, final.delivered) == (FeedOutcome.SUCCEEDED, 1)
    assert final.elapsed_s == pytest.approx(2.5)
    assert final.reason == "a part reached sensor 1 in 2.5 s"


@pytest.mark.parametrize("covered", [None, False, True])
def test_until_present_succeeds_at_once_only_when_the_sensor_is_covered(
    covered: bool | None,
) -> None:
    progress = until_feed(covered).update(100.0, False)
    assert progress.done is bool(covered)
    if covered:
        assert (progress.outcome, progress.delivered, progress.elapsed_s) == (
            FeedOutcome.SUCCEEDED,
            0,
            0.0,
        )
        assert math.isnan(progress.time_per_part_s)
        assert math.isnan(progress.last_delivery_s)


def test_starvation_counts_feeding_time_only() -> None:
    feed = count_feed(5, timeout_s=2.0)
    feed.update(100.0, False)  # ramping up: not feeding
    feed.update(101.0, True)
    assert not feed.update(102.0, True).done  # 1 s fed
    feed.update(102.5, True)  # 1.5 s
    feed.update(103.0, False)  # paused by level control
    assert not feed.update(110.0, False).done  # 7 s paused: does not count
    feed.update(111.0, True)  # resumed (the interval into it is not feeding)
    assert not feed.update(111.25, True).done  # 1.75 s
    assert not feed.update(111.499, True).done  # just before the time-out
    final = feed.update(111.5, True)  # 2.0 s of feeding
    assert final.outcome is FeedOutcome.STARVED
    assert final.elapsed_s == 11.5
    assert final.reason == "starved: no part past sensor 1 for 2.0 s of feeding (0 of 5 delivered)"
    assert math.isnan(final.time_per_part_s)


def test_a_delivery_restarts_the_starvation_time() -> None:
    feed = count_feed(5, timeout_s=2.0)
    feed.update(100.0, True)
    feed.update(101.5, True)
    feed.edge(101.8, 1, 1, False)
    assert not feed.update(103.7, True).done  # 1.9 s since the delivery
    final = feed.update(103.8, True)
    assert (final.outcome, final.delivered) == (FeedOutcome.STARVED, 1)
    assert "(1 of 5 delivered)" in final.reason


def test_cancel_freezes_the_outcome() -> None:
    feed = count_feed(5)
    pass_part(feed, 101.0, 1)
    pass_part(feed, 102.0, 2)
    final = feed.cancel(103.0)
    assert (final.outcome, final.delivered, final.elapsed_s) == (FeedOutcome.CANCELED, 2, 3.0)
    assert final.time_per_part_s == 1.5
    assert final.reason == "canceled by the client (2 of 5 parts delivered)"
    pass_part(feed, 104.0, 3)
    assert feed.update(200.0, True) == final  # starvation cannot happen after the end either
    assert feed.abort(105.0, FeedOutcome.ESTOPPED, "emergency stop: button") == final


def test_abort_freezes_the_outcome_with_the_nodes_reason() -> None:
    feed = until_feed()
    final = feed.abort(104.0, FeedOutcome.FAULTED, "drive fault: heartbeat lost (2.0 s)")
    assert (final.outcome, final.reason) == (
        FeedOutcome.FAULTED,
        "drive fault: heartbeat lost (2.0 s)",
    )
    assert final.elapsed_s == 4.0
    assert feed.cancel(105.0) == final
    feed.edge(105.0, 1, 1, True)
    assert feed.update(106.0, True) == final
    with pytest.raises(ValueError, match=r"outcome=.*SUCCEEDED"):
        count_feed(1).abort(101.0, FeedOutcome.SUCCEEDED, "")


@pytest.mark.parametrize(
    ("mode", "count", "sensor", "timeout", "words"),
    [
        (0, 0, 1, 20.0, "part_count=0: a COUNT goal needs 1..10000 parts"),
        (0, -3, 1, 20.0, "part_count=-3: a COUNT goal needs 1..10000 parts"),
        (0, 10001, 1, 20.0, "part_count=10001: "),
        (0, True, 1, 20.0, "part_count=True: "),
        (1, 2, 1, 20.0, "part_count=2: an UNTIL_PRESENT goal takes no count"),
        (0, 5, 2, 20.0, "sensor_index=2: the feeder has 2 part-present sensors (0..1)"),
        (0, 5, -1, 20.0, "sensor_index=-1: "),
        (0, 5, 1, math.nan, "starvation_timeout_s=nan must be finite and > 0"),
        (0, 5, 1, math.inf, "starvation_timeout_s=inf "),
        (0, 5, 1, 0.0, "starvation_timeout_s=0.0 "),
        (7, 5, 1, 20.0, "mode=7: expected 0 (COUNT) or 1 (UNTIL_PRESENT)"),
    ],
)
def test_refusals_name_the_offending_value(
    mode: int, count: int, sensor: int, timeout: float, words: str
) -> None:
    assert request_refusal(mode, count, sensor, timeout, 2).startswith(words)


def test_acceptable_goals_and_bad_requests() -> None:
    assert request_refusal(0, 1, 0, 0.5, 2) == ""
    assert request_refusal(0, 10000, 1, 20.0, 2) == ""
    assert request_refusal(1, 0, 1, 20.0, 2) == ""
    with pytest.raises(ValueError, match="part_count=0"):
        FeedRequest(FeedMode.COUNT, 0, 1, 20.0)
    assert FeedRequest(1, 0, 0, 1.0).mode is FeedMode.UNTIL_PRESENT  # type: ignore[arg-type]


def test_non_finite_times_are_refused_with_the_value() -> None:
    feed = count_feed(1)
    with pytest.raises(ValueError, match="t_s=nan"):
        feed.update(math.nan, True)
    with pytest.raises(ValueError, match="t_s=inf"):
        feed.edge(math.inf, 1, 1, False)
    with pytest.raises(ValueError, match="t_start_s=nan"):
        count_feed(1, t0=math.nan)
