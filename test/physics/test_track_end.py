"""The track-end stopper's queue (ROS-free): slots, joins, picks, a full track, what the sensors
see, and the queue driven by the exact physics core the way the platform simulator drives it."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import pytest

from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.simulation import EventKind, FeederSimulator, PartSpec
from feeder_ros.physics.track_end import (
    COINCIDENT_M,
    MIN_CORE_TRACK_M,
    Join,
    Picks,
    TrackEndQueue,
    covered_sensors,
    pick_edges,
    start_blocked,
)
from feeder_ros.sensors.part_presence import PartSensorArray, SensorEdge

T, L = 0.1, 0.01  # stopper at 10 cm, parts 1 cm long
NO_EXITS = (np.zeros(0), np.zeros(0, np.int64))


def _queue_of(*parts: int) -> TrackEndQueue:
    queue = TrackEndQueue(T, L)
    for k, part in enumerate(parts):
        queue.join(part, float(k))
    return queue


# -- slots, tail, picks ------------------------------------------------------------------------
def test_slots_and_tail_follow_joins_and_picks() -> None:
    queue = TrackEndQueue(T, L)
    assert queue.tail_m == T
    assert queue.core_track_length_m == T
    assert len(queue) == 0
    joins = [queue.join(part, t) for part, t in ((4, 1.0), (2, 1.5), (7, 2.0))]
    assert [j.slot_m for j in joins] == pytest.approx([0.10, 0.09, 0.08], abs=1e-15)
    assert queue.parts == (4, 2, 7)
    assert queue.tail_m == pytest.approx(0.07, abs=1e-15)
    assert queue.core_track_length_m == queue.tail_m
    assert queue.slots() == pytest.approx({4: 0.10, 2: 0.09, 7: 0.08}, abs=1e-15)

    assert queue.request_pick() == 4  # asked for; carried out by take_picks
    assert queue.parts == (4, 2, 7)
    assert queue.pending_picks == 1
    picks = queue.take_picks()
    assert picks.parts == (4,)
    assert picks.before_m == pytest.approx({4: 0.10, 2: 0.09, 7: 0.08}, abs=1e-15)
    # the rest moved up one slot at once, and the tail (the core's track end) with them
    assert queue.slots() == pytest.approx({2: 0.10, 7: 0.09}, abs=1e-15)
    assert queue.tail_m == pytest.approx(0.08, abs=1e-15)
    assert queue.picked_total == 1
    assert queue.pending_picks == 0
    assert not queue.take_picks()  # nothing asked for: no picks

    queue.join(9, 3.0)
    assert queue.slots()[9] == pytest.approx(0.08, abs=1e-15)


def test_picks_asked_for_in_a_row_take_the_front_parts_in_order() -> None:
    queue = _queue_of(1, 2, 3)
    assert [queue.request_pick(), queue.request_pick()] == [1, 2]
    ok, message = queue.answer_pick(4.25)
    assert ok
    assert message == "picked part 3 at t = 4.250000 s"
    ok, message = queue.answer_pick(4.25)
    assert not ok
    assert message == "no part to pick at the stopper: 3 queued, 3 of them being picked"
    assert queue.take_picks().parts == (1, 2, 3)
    assert len(queue) == 0
    assert queue.tail_m == T
    assert queue.picked_total == 3

    queue.periodic_pick()  # the robot finds nothing: a miss, counted
    queue.periodic_pick()
    assert queue.picks_missed == 2
    assert queue.pending_picks == 0


def test_a_part_joins_once_and_not_before_the_last_join() -> None:
    queue = _queue_of(1)
    with pytest.raises(ParameterError, match="part 1 is already queued"):
        queue.join(1, 5.0)
    with pytest.raises(ParameterError, match="before the last join"):
        queue.join(2, -1.0)
    with pytest.raises(ParameterError, match="part_length_m"):
        TrackEndQueue(T, 0.0)


def test_moving_the_stopper_moves_the_queue() -> None:
    queue = _queue_of(1, 2)
    queue.set_track_length(0.2)
    assert queue.slots() == pytest.approx({1: 0.2, 2: 0.19}, abs=1e-15)
    assert queue.tail_m == pytest.approx(0.18, abs=1e-15)


def test_a_full_track_refuses_feeds_and_keeps_the_core_track_positive() -> None:
    queue = TrackEndQueue(0.03, L)
    start = 0.005
    for part in range(2):
        queue.join(part, float(part))
    assert queue.tail_m == pytest.approx(0.01)
    assert not queue.is_full(start)
    assert queue.admit_feed(start)
    assert queue.feeds_skipped == 0
    queue.join(2, 2.0)  # tail at 0: a part put down at 5 mm would stand in the queue
    assert queue.is_full(start)
    assert not queue.admit_feed(start)
    assert not queue.admit_feed(start)
    assert queue.feeds_skipped == 2
    assert queue.core_track_length_m == pytest.approx(MIN_CORE_TRACK_M, abs=1e-15)
    queue.join(3, 3.0)  # pushed past the track's start (a part put down behind the feed point)
    assert queue.tail_m == pytest.approx(-0.01)
    assert queue.core_track_length_m == MIN_CORE_TRACK_M
    FeederParameters(track_length_m=queue.core_track_length_m)  # a valid core track length
    assert queue.request_pick() == 0
    queue.take_picks()
    assert queue.tail_m == pytest.approx(0.0, abs=1e-15)
    assert queue.is_full(start)
    queue.clear()
    assert len(queue) == 0
    assert queue.tail_m == 0.03
    assert queue.feeds_skipped == 0


def test_status_reports_the_queue() -> None:
    queue = _queue_of(5, 6)
    queue.periodic_pick()
    queue.take_picks()
    queue.admit_feed(0.2)  # behind the tail (0.09): no room
    assert queue.status() == {
        "parts_queued": "1",
        "queue_tail_m": "0.09",
        "parts_picked_total": "1",
        "picks_missed_queue_empty": "0",
        "feeds_skipped_track_full": "1",
    }


# -- the bowl's exit ----------------------------------------------------------------------------
def test_a_part_within_a_part_length_of_the_start_blocks_a_feed() -> None:
    start = 0.02
    assert not start_blocked([], start, L)  # an empty track
    assert not start_blocked([np.nan, np.nan], start, L)  # parts gone
    assert start_blocked([start], start, L)  # on the spot (a track that does not move)
    assert start_blocked([0.1, start + 0.0099], start, L)  # ahead, overlapping
    assert start_blocked([start - 0.0099], start, L)  # behind it, overlapping too
    assert not start_blocked([start + L, start - L, np.nan], start, L)  # touching: room
    assert start_blocked([start + L - 2 * COINCIDENT_M], start, L)  # more than round-off
    assert not start_blocked(np.array([0.05, 0.1]), start, L)
    # parts of length 0 are points: only one at the start itself (to round-off) blocks
    assert start_blocked([start + 0.5 * COINCIDENT_M], start, 0.0)
    assert not start_blocked([start + 2 * COINCIDENT_M, start - 1e-6], start, 0.0)


# -- joins within a chunk (synthetic core output) ----------------------------------------------
def _linear_chunk(
    t0: float, t1: float, fronts: list[float], v: float, exits: dict[int, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Samples every ms of parts moving at ``v`` from ``fronts`` at ``t0``; nan from each part's
    exit time on (as the core shows a part that left)."""
    times = np.linspace(t0, t1, round((t1 - t0) * 1000) + 1)
    track = np.array(fronts)[None, :] + v * (times - t0)[:, None]
    for part, t_exit in exits.items():
        track[times >= t_exit, part] = np.nan
    return times, track


def test_the_first_join_of_a_chunk_is_the_cores_exit_and_later_ones_cross_their_slot() -> None:
    v = 0.02
    queue = TrackEndQueue(T, L)
    # part 0 reaches the core's track end (T) at 0.1 s; part 1, 12 mm behind, crosses its slot
    # (T - L) at 0.2 s and runs on in the core to T, leaving it at 0.7 s (same chunk)
    fronts = [T - 0.002, T - 0.014, 0.0]
    times, track = _linear_chunk(0.0, 1.0, fronts, v, {0: 0.1, 1: 0.7})
    exit_t, exit_part = np.array([0.1, 0.7]), np.array([0, 1])
    joins = queue.settle(times, track, exit_t, exit_part)
    assert [(j.part, j.slot_m) for j in joins] == [(0, T), (1, pytest.approx(T - L))]
    assert joins[0].t_s == 0.1  # the core's exact event
    assert joins[1].t_s == pytest.approx(0.2, abs=1e-9)  # linear motion: interpolation is exact
    # overlaid: each stands at its slot from its join on, never past it; part 2 moves on
    assert np.all(track[times >= 0.1, 0] == T)
    assert np.all(track[times >= joins[1].t_s, 1] == pytest.approx(T - L))
    assert np.nanmax(track[:, 1]) <= T - L + 1e-15
    assert np.allclose(track[:, 2], v * times)
    assert queue.tail_m == pytest.approx(T - 2 * L)
    mask = queue.queued_at(0.15, 3)
    assert mask.tolist() == [True, False, False]
    assert queue.queued_at(0.5, 3).tolist() == [True, True, False]


def test_a_part_past_its_slot_when_the_part_ahead_joins_is_set_back_at_once() -> None:
    """Parts are points to the physics: one 4 mm behind another (less than a part length) is past
    the tail when the first joins; it joins with it, at its slot."""
    v = 0.02
    queue = TrackEndQueue(T, L)
    times, track = _linear_chunk(0.0, 0.3, [T - 0.002, T - 0.006], v, {0: 0.1, 1: 0.3})
    joins = queue.settle(times, track, np.array([0.1, 0.3]), np.array([0, 1]))
    assert [j.t_s for j in joins] == [0.1, 0.1]
    assert np.all(track[times >= 0.1, 1] == pytest.approx(T - L))


def test_a_part_past_the_tail_at_the_chunk_end_joins_from_the_samples() -> None:
    """The core's track end stays at the old tail for the whole chunk: a part that crossed the new
    tail by the chunk's end joins from the samples, and the core's exit for it next chunk (at once,
    at its start) is not a second join."""
    v = 0.02
    queue = TrackEndQueue(T, L)
    # part 0 joins at 0.1 s; part 1, 13 mm behind it, crosses T - L at 0.25 s, still in the core
    times, track = _linear_chunk(0.0, 0.3, [T - 0.002, T - 0.015], v, {0: 0.1})
    joins = queue.settle(times, track, np.array([0.1]), np.array([0]))
    assert [j.part for j in joins] == [0, 1]
    assert joins[1].t_s == pytest.approx(0.25, abs=1e-9)
    assert np.all(track[times >= 0.25, 1] == pytest.approx(T - L))
    # the next chunk: the core (track end now T - 2L) lets part 1 go at its start
    times, track = _linear_chunk(0.3, 0.4, [np.nan, np.nan], v, {})
    assert queue.settle(times, track, np.array([0.3]), np.array([1])) == []
    assert queue.parts == (0, 1)
    assert np.all(track == np.array([T, T - L]))


def test_a_part_picked_before_the_core_let_it_go_is_gone_from_the_samples() -> None:
    v = 0.02
    queue = TrackEndQueue(T, L)
    times, track = _linear_chunk(0.0, 0.3, [T - 0.002, T - 0.015], v, {0: 0.1})
    queue.settle(times, track, np.array([0.1]), np.array([0]))
    assert queue.parts == (0, 1)  # part 1 from the samples; still simulated by the core
    queue.request_pick()
    queue.request_pick()
    assert queue.take_picks().parts == (0, 1)
    # the core still shows part 1 moving (its exit comes later): it is not on the track any more
    times, track = _linear_chunk(0.3, 0.5, [np.nan, T - 0.004], v, {1: 0.45})
    assert queue.settle(times, track, np.array([0.45]), np.array([1])) == []
    assert np.isnan(track[:, 1]).all()
    assert len(queue) == 0


# -- what the sensors see ------------------------------------------------------------------------
def test_covered_sensors_is_a_light_barrier() -> None:
    fronts = np.array([0.1, 0.09, np.nan])
    # covered while front - L < p <= front: the row covers (0.08, 0.1]
    positions = [0.0801, 0.08, 0.095, 0.1, 0.1001]
    assert covered_sensors(positions, L, fronts) == [True, False, True, True, False]


def _edges(edges: list[SensorEdge]) -> list[tuple[float, int, int, bool]]:
    return [(e.t_s, e.sensor_index, e.part, e.present) for e in edges]


def _arrive(
    queue: TrackEndQueue, sensors: PartSensorArray, fronts: list[float], t_end: float
) -> list[tuple[float, int, int, bool]]:
    """Parts from ``fronts`` at 20 mm/s in one chunk of an empty queue (the core's track end at T:
    each leaves the core there); the sensors' edges."""
    v = 0.02
    exits = {k: (T - x) / v for k, x in enumerate(fronts)}
    times, track = _linear_chunk(0.0, t_end, fronts, v, exits)
    order = sorted(exits, key=exits.__getitem__)
    queue.settle(times, track, np.array([exits[k] for k in order]), np.array(order))
    return _edges(sensors.update(times, track))


def _pick(
    queue: TrackEndQueue, sensors: PartSensorArray, t: float, parts: int, count: int = 1
) -> list[tuple[float, int, int, bool]]:
    """``count`` picks asked for, carried out at the start of a chunk from ``t`` (``parts``
    columns, none of them in the core any more): the chunk's edges."""
    for _ in range(count):
        queue.request_pick()
    picks = queue.take_picks()
    times, track = _linear_chunk(t, t + 0.5, [np.nan] * parts, 0.0, {})
    before = queue.before_picks(track[0], picks)
    queue.settle(times, track, *NO_EXITS)
    return _edges(pick_edges(sensors, times, track, before, picks))


def test_sensors_see_parts_arrive_sit_and_leave_after_picks() -> None:
    """Sensors under slot 0 (9.5 cm), slot 1 (8.5 cm) and behind the queue (7.5 cm): edges as the
    parts move in, none while they sit, and at a pick only what a light barrier shows, at the
    pick time exactly."""
    sensors = PartSensorArray([0.095, 0.085, 0.075], L)
    queue = TrackEndQueue(T, L)
    # part 0 from 7 cm joins at T at 1.5 s; part 1 from 5.5 cm crosses its slot (9 cm) at 1.75 s
    edges = _arrive(queue, sensors, [0.07, 0.055], 2.0)
    expected = [
        (0.25, 2, 0, True),
        (0.75, 1, 0, True),
        (0.75, 2, 0, False),
        (1.0, 2, 1, True),
        (1.25, 0, 0, True),  # part 0 now covers 9.5 cm for good
        (1.25, 1, 0, False),
        (1.5, 1, 1, True),  # part 1 now covers 8.5 cm for good
        (1.5, 2, 1, False),
    ]
    assert sorted((round(t, 9), s, p, on) for t, s, p, on in edges) == sorted(expected)
    assert queue.slots() == pytest.approx({0: T, 1: T - L})
    for k in range(5):  # sitting: chunk after chunk, no edge
        times, track = _linear_chunk(2.0 + k, 3.0 + k, [np.nan, np.nan], 0.0, {})
        before = queue.before_picks(track[0], Picks())
        queue.settle(times, track, *NO_EXITS)
        assert pick_edges(sensors, times, track, before, Picks()) == []  # (no picks: as it is)
    # first pick: part 0 leaves slot 0 as part 1 moves in: 9.5 cm stays covered (no edge); 8.5 cm
    # becomes free: part 1's falling edge, at the pick time exactly
    assert _pick(queue, sensors, 7.0, parts=2) == [(7.0, 1, 1, False)]
    assert queue.slots() == {1: T}
    # second pick: the last part leaves; 9.5 cm becomes free
    assert _pick(queue, sensors, 7.5, parts=2) == [(7.5, 0, 1, False)]
    assert len(queue) == 0


def test_a_jump_of_two_slots_shows_only_the_sensor_that_went_free() -> None:
    """Four parts queued, two picked at once: the parts jump two slots, over the sensors under
    slots 0 and 1 (covered before and after: no edge), and uncover the one under slot 3."""
    sensors = PartSensorArray([0.095, 0.085, 0.065], L)
    queue = TrackEndQueue(T, L)
    _arrive(queue, sensors, [0.07, 0.055, 0.04, 0.025], 4.0)
    assert queue.slots() == pytest.approx({0: 0.1, 1: 0.09, 2: 0.08, 3: 0.07})
    assert covered_sensors(sensors.positions_m, L, np.array([0.1, 0.09, 0.08, 0.07])) == [
        True,
        True,
        True,
    ]
    assert _pick(queue, sensors, 5.0, parts=4, count=2) == [(5.0, 2, 3, False)]
    assert queue.slots() == pytest.approx({2: 0.1, 3: 0.09})
    assert queue.picked_total == 2


# -- with the exact physics core, as the platform simulator runs it --------------------------------
PLANT = FeederParameters(
    damping_ns_per_m=200.0, drive_frequency_hz=20.0, drive_amplitude_n=40.0, track_length_m=0.04
)  # parts move about 16 mm/s


def _follow(sim: FeederSimulator, queue: TrackEndQueue) -> None:
    if queue.core_track_length_m != sim.params.track_length_m:
        sim.set_parameters(sim.params.with_changes(track_length_m=queue.core_track_length_m))


class Run(NamedTuple):
    times: np.ndarray  # every chunk's samples (a chunk's end and the next one's start both)
    track: np.ndarray  # track positions, the queue written in
    carrier_x_m: np.ndarray
    joins: list[Join]


def _run(
    sim: FeederSimulator,
    queue: TrackEndQueue,
    t_end: float,
    chunk_s: float,
    between: Callable[[np.ndarray], None] | None = None,
) -> Run:
    """Advance in chunks the way the node does: picks asked for carried out at a chunk's start,
    samples every ms and at both chunk ends, the core's track end at the tail; ``between`` gets
    each chunk's last row of the core's track positions (before the queue is written in)."""
    rows_t, rows, carrier, joins = [], [], [], []
    while sim.time_s < t_end - 1e-12:
        t0, t1 = sim.time_s, min(sim.time_s + chunk_s, t_end)
        grid = np.arange(np.ceil(t0 * 1e3), np.floor(t1 * 1e3) + 1) / 1e3
        times = np.union1d(grid[(grid >= t0) & (grid <= t1)], (t0, t1))
        queue.take_picks()
        _follow(sim, queue)
        result = sim.advance(t1, times)
        track = result.part_x_m - result.carrier_x_m[:, None]
        last = track[-1].copy()
        exits = result.event_kind == EventKind.PART_EXIT
        joins += queue.settle(times, track, result.event_t_s[exits], result.event_part[exits])
        _follow(sim, queue)
        if between is not None:
            between(last)
        rows_t.append(times)
        rows.append(track)
        carrier.append(result.carrier_x_m)
    width = max(r.shape[1] for r in rows)
    padded = [np.pad(r, ((0, 0), (0, width - r.shape[1])), constant_values=np.nan) for r in rows]
    return Run(np.concatenate(rows_t), np.vstack(padded), np.concatenate(carrier), joins)


def test_parts_queue_at_their_slots_with_the_physics_core() -> None:
    """Four parts 15 mm apart on a 4 cm track: each stops at its slot and stays there, never shown
    past it; the core's track end follows the tail; the carrier moves as on an open track; after
    a pick the tail moves up and a new part joins there."""
    parts = [PartSpec(position_m=x) for x in (0.030, 0.015, 0.0, -0.015)]
    sim = FeederSimulator(PLANT, parts)
    queue = TrackEndQueue(PLANT.track_length_m, L)
    run = _run(sim, queue, 6.0, chunk_s=0.05)
    assert queue.parts == (0, 1, 2, 3)
    slots = [queue.slot_m(k) for k in range(4)]
    assert slots == pytest.approx([0.04, 0.03, 0.02, 0.01])
    assert [(j.part, j.slot_m) for j in run.joins] == list(enumerate(slots))
    assert np.all(run.track[-1] == slots)
    for k, join in enumerate(run.joins):
        column = run.track[:, k]
        assert np.nanmax(column) <= slots[k] + 1e-12  # never past its slot
        assert np.all(column[run.times >= join.t_s] == slots[k])  # there from its join on
        moving = column[run.times < join.t_s]
        assert moving[-1] == pytest.approx(slots[k], abs=0.0002)  # arrived (16 mm/s, 1 ms)
        assert moving[-1] < slots[k]
    assert sim.params.track_length_m == pytest.approx(0.0, abs=1e-9)  # the core ends at the tail
    assert queue.is_full(0.0)  # a feed at 0 would be refused
    # the core's moving track end left the carrier alone
    unique, first = np.unique(run.times, return_index=True)
    open_track = FeederSimulator(PLANT, parts).advance(6.0, unique)
    np.testing.assert_allclose(run.carrier_x_m[first], open_track.carrier_x_m, rtol=0, atol=1e-12)

    queue.request_pick()
    _run(sim, queue, 6.5, chunk_s=0.05)
    assert queue.parts == (1, 2, 3)
    assert queue.picked_total == 1
    assert sim.params.track_length_m == pytest.approx(0.01)
    assert not queue.is_full(0.0)
    new = sim.spawn_part(PartSpec(position_m=0.0))
    run = _run(sim, queue, 8.0, chunk_s=0.05)
    assert queue.parts == (1, 2, 3, new)
    assert run.track[-1, [1, 2, 3, new]] == pytest.approx([0.04, 0.03, 0.02, 0.01])
    assert np.nanmax(run.track[:, new]) <= 0.01 + 1e-12


def test_parts_closer_than_a_part_length_still_queue_one_per_slot() -> None:
    """Parts 6 mm apart (the physics lets them overlap) and long chunks (several joins each):
    every part ends in its own slot, joined in track order; once the part ahead has joined, none
    is shown past its slot."""
    parts = [PartSpec(position_m=0.03 - 0.006 * k) for k in range(4)]
    sim = FeederSimulator(PLANT, parts)
    queue = TrackEndQueue(PLANT.track_length_m, L)
    run = _run(sim, queue, 4.0, chunk_s=0.5)
    assert queue.parts == (0, 1, 2, 3)
    assert [j.slot_m for j in run.joins] == pytest.approx([0.04, 0.03, 0.02, 0.01])
    times = [j.t_s for j in run.joins]
    assert times == sorted(times)
    assert times[1] == times[0]  # 6 mm behind: past its slot (3 cm) when part 0 joined at 4 cm
    for k in range(1, 4):
        later = run.track[run.times >= times[k - 1], k]
        assert np.nanmax(later) <= queue.slot_m(k) + 1e-12
        assert later[-1] == pytest.approx(queue.slot_m(k))


def test_reading_the_parts_between_chunks_changes_nothing() -> None:
    """Before a feed the node reads where the parts are (PlatformSimulator._bowl_feed, through
    FeederSimulator.track_positions): the positions the last chunk ended with, NaN for parts the
    core let go; the run is the same as without the reads (a part joined from the samples is
    still let go at the next chunk's start)."""
    parts = [PartSpec(position_m=0.03 - 0.006 * k) for k in range(4)]
    plain = _run(FeederSimulator(PLANT, parts), TrackEndQueue(PLANT.track_length_m, L), 4.0, 0.5)
    sim = FeederSimulator(PLANT, parts)
    queue = TrackEndQueue(PLANT.track_length_m, L)
    queued_in_core = 0

    def read(last: np.ndarray) -> None:
        nonlocal queued_in_core
        x = sim.track_positions()
        on = ~np.isnan(x)  # still in the core
        np.testing.assert_allclose(x[on], last[on], rtol=0, atol=1e-12)
        assert np.all(np.isnan(last[~on]))
        queued_in_core += sum(1 for part in queue.parts if on[part])

    reads = _run(sim, queue, 4.0, 0.5, between=read)
    assert queued_in_core > 0  # the case that matters: joined, not yet let go by the core
    assert reads.joins == plain.joins
    np.testing.assert_array_equal(reads.track, plain.track)
    np.testing.assert_array_equal(reads.carrier_x_m, plain.carrier_x_m)
