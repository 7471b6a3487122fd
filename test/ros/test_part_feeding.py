"""Part feeding with real processes: the ``feed_parts`` action and track level control of the
drive interface, against the platform simulator (the demo cell's feeder, config/cell.yaml), driven
at a fixed set point by an in-process cell controller (the example's, with its heartbeat).

What is checked is what reaches the wire: the sensor edges the simulator publishes, the drive's
state and output, and the action's feedback and result.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.action.client import ActionClient
from ros_test_tools import DrainedProcess, call, demo_cell_file, probe_node, wait_until
from std_srvs.srv import Trigger

from feeder_ros.action import FeedParts
from feeder_ros.cell import load_cell, parameters_document
from feeder_ros.cli.cell import node_executables
from feeder_ros.examples.cell_controller import CellController
from feeder_ros.msg import DriveState, PartSensorEvent, PartStateArray
from feeder_ros.srv import SetDrive

BIN = Path(sys.executable).parent
RAMP_S = 0.5  # the set point's ramp; the drive's amplitude rate limit (50 %/s) makes 1.2 s of 60 %
STOP_RAMP_S = 60.0 / 50.0


@dataclass
class Wire:
    """What the probe heard: sensor edges and drive states, with their receive times."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    edges: list[tuple[float, int, int, bool]] = field(default_factory=list)  # stamp, sensor, id, on
    states: list[tuple[float, DriveState]] = field(default_factory=list)

    def on_edge(self, message: PartSensorEvent) -> None:
        stamp = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
        with self.lock:
            self.edges.append((stamp, message.sensor_index, message.part_id, message.present))

    def on_state(self, message: DriveState) -> None:
        with self.lock:
            self.states.append((time.monotonic(), message))

    def passed(self, sensor: int, start: float, end: float = math.inf) -> list[int]:
        """Parts whose falling edge at ``sensor`` is stamped in [start, end)."""
        with self.lock:
            return [p for t, s, p, on in self.edges if s == sensor and not on and start <= t < end]

    def goal_ends(self) -> list[DriveState]:
        """The drive states that first said a feed_parts goal had ended."""
        with self.lock:
            states = [m for _, m in self.states]
        return [m for p, m in itertools.pairwise(states) if p.feed_active and not m.feed_active]

    def last_state(self) -> DriveState | None:
        with self.lock:
            return self.states[-1][1] if self.states else None


@contextlib.contextmanager
def feeding_cell(
    tmp_path: Path,
    namespace: str,
    simulator: dict[str, Any] | None = None,
    drive: dict[str, Any] | None = None,
) -> Iterator[tuple[Any, Wire, CellController, Any]]:
    """Simulator and drive interface as processes, the drive configured and active at 30 Hz /
    60 % (not started); yields the probe, what it heard, the controller and a feed_parts client."""
    cell = load_cell(
        demo_cell_file(
            tmp_path,
            namespace,
            without=("vehicle_estimator", "speed_monitor"),
            parameters={
                "platform_simulator": simulator or {},
                "drive_interface": {
                    "speed_model_enabled": False,
                    "speed_trim": {"enabled": False},
                    **(drive or {}),
                },
            },
        ),
        node_executables(),
    )
    parameters = tmp_path / "parameters.yaml"
    parameters.write_text(parameters_document(cell), encoding="utf-8")
    processes = [
        DrainedProcess([str(BIN / launch.executable), *launch.ros_arguments(parameters)])
        for launch in cell.nodes
    ]
    wire = Wire()
    try:
        with probe_node() as probe:
            probe.create_subscription(
                PartSensorEvent, f"{namespace}/parts/sensor_events", wire.on_edge, 100
            )
            probe.create_subscription(DriveState, f"{namespace}/drive/state", wire.on_state, 100)
            controller = CellController(namespace, context=probe.context)
            executor = probe.executor
            assert executor is not None
            executor.add_node(controller)
            client = ActionClient(probe, FeedParts, f"{namespace}/feed_parts")
            try:
                controller.bring_up()
                answer = controller.call(
                    SetDrive,
                    "set_drive",
                    SetDrive.Request(frequency_hz=30.0, amplitude_percent=60.0, ramp_time_s=RAMP_S),
                )
                assert answer.result != SetDrive.Response.REFUSED, answer.reason
                assert client.wait_for_server(timeout_sec=30.0)
                # the drive has heard the controller's heartbeat once it starts (just after
                # start-up the topic is still being discovered): start, then stop at once
                assert controller.start(wait_s=30.0)
                assert controller.trigger("stop")
                assert wait_until(
                    lambda: (
                        wire.last_state() is not None
                        and wire.last_state().state == DriveState.STATE_IDLE
                    ),
                    30.0,
                )
                # the simulator is up once its sensor edges flow (initial parts under a sensor
                # do not move without the drive: wait for its parts/state instead)
                assert wait_until(lambda: wire.last_state() is not None, 30.0)
                yield probe, wire, controller, client
            finally:
                # (the action client goes with the probe: destroyed while the probe's executor
                # thread spins, it can leave that thread a dangling handle)
                executor.remove_node(controller)
                controller.destroy_node()
    finally:
        for process in processes:
            if process.poll() is None:
                process.send_signal(2)
        for process in processes:
            try:
                process.wait(timeout=15)
            except Exception:
                process.kill()
                process.wait()
                print(f"--- did not stop on Ctrl-C:\n{process.output()[-3000:]}")


class Goal:
    """A feed_parts goal sent from the test thread: its feedback and its result."""

    def __init__(self, client: Any, mode: int, count: int, sensor: int, timeout_s: float = 0.0):
        self.feedback: list[tuple[float, Any]] = []
        self.sent_at = time.monotonic()
        future = client.send_goal_async(
            FeedParts.Goal(
                mode=mode, part_count=count, sensor_index=sensor, starvation_timeout_s=timeout_s
            ),
            feedback_callback=lambda m: self.feedback.append((time.monotonic(), m.feedback)),
        )
        assert wait_until(future.done, 30.0), "the goal was not answered"
        self.handle = future.result()
        assert self.handle.accepted  # every goal is accepted; a refused one ends REFUSED
        self._result = self.handle.get_result_async()
        self.result_at = math.nan

    def result(self, timeout_s: float) -> Any:
        assert wait_until(self._result.done, timeout_s), f"no result within {timeout_s} s"
        if math.isnan(self.result_at):
            self.result_at = time.monotonic()
        return self._result.result().result


def _now_s(probe: Any) -> float:
    return probe.get_clock().now().nanoseconds * 1e-9


@pytest.mark.timeout(180)
def test_feed_parts_delivers_exactly_n_parts_and_stops_the_feeder(tmp_path: Path) -> None:
    with feeding_cell(tmp_path, "/feed_count/feeder") as (probe, wire, _controller, client):
        start = _now_s(probe)
        goal = Goal(client, FeedParts.Goal.MODE_COUNT, 3, sensor=1)
        result = goal.result(90.0)
        end = _now_s(probe)
        assert result.outcome == FeedParts.Result.OUTCOME_SUCCEEDED, result.reason
        assert result.parts_delivered == 3
        passed = wire.passed(1, start, end)
        assert len(passed) == 3, passed  # exactly the parts asked for passed the sensor
        # the goal ended once the output was off: the drive state that says so (published
        # before the result; the two arrive by different readers) has the output at zero
        assert wait_until(lambda: len(wire.goal_ends()) == 1, 5.0)
        state = wire.goal_ends()[0]
        assert state.amplitude_percent == 0.0
        assert state.state == DriveState.STATE_IDLE
        assert state.feed_parts_delivered == 3
        time.sleep(3.0)
        assert wire.passed(1, end) == []  # nothing more passed: the feeder stopped
        # feedback counted the parts up, with the elapsed time
        counts = [f.parts_delivered for _, f in goal.feedback]
        assert counts == sorted(counts)
        assert counts[-1] >= 2
        assert result.time_per_part_s == pytest.approx(result.elapsed_s / 3)


@pytest.mark.timeout(180)
def test_cancel_starvation_estop_and_bad_goals_end_with_their_reasons(tmp_path: Path) -> None:
    with feeding_cell(tmp_path, "/feed_abort/feeder") as (probe, wire, _controller, client):
        # bad goals: refused with the value named, the drive untouched
        for mode, count, sensor, timeout, words in (
            (FeedParts.Goal.MODE_COUNT, 0, 1, 0.0, "part_count=0"),
            (FeedParts.Goal.MODE_COUNT, 10001, 1, 0.0, "part_count=10001"),
            (FeedParts.Goal.MODE_COUNT, 2, 5, 0.0, "sensor_index=5"),
            (FeedParts.Goal.MODE_COUNT, 2, 1, math.nan, "starvation_timeout_s=nan"),
            (7, 1, 1, 0.0, "mode=7"),
        ):
            result = Goal(client, mode, count, sensor, timeout).result(10.0)
            assert result.outcome == FeedParts.Result.OUTCOME_REFUSED
            assert words in result.reason, result.reason
        state = wire.last_state()
        assert state is not None
        assert state.state == DriveState.STATE_IDLE

        # cancel: ramps to zero, the answer within the stop ramp (plus delivery)
        goal = Goal(client, FeedParts.Goal.MODE_COUNT, 500, sensor=1)
        assert wait_until(lambda: wire.last_state().state == DriveState.STATE_RUNNING, 20.0)
        second = Goal(client, FeedParts.Goal.MODE_COUNT, 1, sensor=1).result(10.0)
        assert second.outcome == FeedParts.Result.OUTCOME_REFUSED
        assert "another feed_parts goal is running" in second.reason
        asked = time.monotonic()
        cancel = goal.handle.cancel_goal_async()
        assert wait_until(cancel.done, 10.0)
        result = goal.result(10.0)
        assert result.outcome == FeedParts.Result.OUTCOME_CANCELED, result.reason
        assert goal.result_at - asked <= STOP_RAMP_S + 1.0
        assert wait_until(lambda: len(wire.goal_ends()) == 1, 5.0)
        assert wire.goal_ends()[0].amplitude_percent == 0.0

        # e-stop while feeding: ESTOPPED at once
        goal = Goal(client, FeedParts.Goal.MODE_COUNT, 500, sensor=1)
        assert wait_until(lambda: wire.last_state().state == DriveState.STATE_RUNNING, 20.0)
        assert call(probe, Trigger, "/feed_abort/feeder/emergency_stop", Trigger.Request()).success
        result = goal.result(5.0)
        assert result.outcome == FeedParts.Result.OUTCOME_ESTOPPED
        assert "emergency stop" in result.reason
        # while latched, a goal is refused with the reason
        refused = Goal(client, FeedParts.Goal.MODE_COUNT, 1, sensor=1).result(10.0)
        assert refused.outcome == FeedParts.Result.OUTCOME_REFUSED
        assert "emergency stop latched" in refused.reason
        assert call(probe, Trigger, "/feed_abort/feeder/reset_fault", Trigger.Request()).success


@pytest.mark.timeout(120)
def test_a_feeder_without_parts_starves_the_goal_after_its_feeding_time(tmp_path: Path) -> None:
    empty = {"initial_parts": 0, "feed_interval_s": 0.0}
    with feeding_cell(tmp_path, "/feed_starve/feeder", simulator=empty) as (
        _probe,
        wire,
        _,
        client,
    ):
        goal = Goal(client, FeedParts.Goal.MODE_COUNT, 2, sensor=1, timeout_s=2.0)
        result = goal.result(30.0)
        assert result.outcome == FeedParts.Result.OUTCOME_STARVED, result.reason
        assert "2.0 s" in result.reason
        assert result.parts_delivered == 0
        assert math.isnan(result.time_per_part_s)
        # the time-out counts feeding time: at least 2 s after the output came on
        assert result.elapsed_s >= 2.0
        assert wait_until(lambda: len(wire.goal_ends()) == 1, 5.0)
        assert wire.goal_ends()[0].amplitude_percent == 0.0


def _stamp(message: Any) -> float:
    return float(message.header.stamp.sec) + float(message.header.stamp.nanosec) * 1e-9


@dataclass(frozen=True)
class LevelCycles:
    """What :func:`_check_level_cycles` measured on the wire."""

    pause_delays_s: list[float]  # per stop: full sensor's covering edge -> first output at zero
    resume_waits_s: list[float]  # per resume: low sensor free -> the drive out of PAUSED


def _level_cycles(states: list[DriveState]) -> int:
    """Level pauses the drive came out of: runs of PAUSED states with a RUNNING one after."""
    cycles, paused = 0, False
    for message in states:
        if message.state == DriveState.STATE_PAUSED:
            paused = True
        elif message.state == DriveState.STATE_RUNNING and paused:
            cycles, paused = cycles + 1, False
    return cycles


def _check_level_cycles(
    states: list[DriveState],
    edges: list[tuple[float, int, int, bool]],
    off_delay: float,
    on_delay: float,
    full_sensor: int = 0,
    low_sensor: int = 1,
) -> LevelCycles:
    """Level control (two sensors) as the wire shows it: paused only for a full track, with the
    output at zero; no part pushed onto a full track longer than the off delay plus the ramp to
    zero (from the full sensor's covering edge to the first output at zero); every resume after
    the low sensor had been free for the on delay."""
    paused_states = [m for m in states if m.state == DriveState.STATE_PAUSED]
    assert all("track full" in m.pause_reason for m in paused_states)
    assert all(m.level_state == DriveState.LEVEL_FULL for m in paused_states)
    assert all(m.amplitude_percent == 0.0 for m in paused_states)
    full_on = [t for t, s, _, on in edges if s == full_sensor and on]
    stopped = [
        _stamp(m)
        for prev, m in itertools.pairwise(states)
        if m.amplitude_percent == 0.0 and prev.amplitude_percent > 0.0
    ]
    delays = []
    for t_zero in stopped:
        covered = [t for t in full_on if t <= t_zero]
        if not covered:
            continue  # a stop that was no level pause (none here: the drive never stops)
        delays.append(t_zero - covered[-1])
        assert delays[-1] <= off_delay + STOP_RAMP_S + 0.3, (t_zero, covered[-1])
    resumed = [
        _stamp(m)
        for prev, m in itertools.pairwise(states)
        if prev.state == DriveState.STATE_PAUSED and m.state != DriveState.STATE_PAUSED
    ]
    low_off = [t for t, s, _, on in edges if s == low_sensor and not on]
    waits = []
    for t_resume in resumed:
        freed = [t for t in low_off if t <= t_resume]
        assert freed, "resumed without the low sensor clearing"
        waits.append(t_resume - freed[-1])
        assert waits[-1] >= on_delay - 0.05
    return LevelCycles(delays, waits)


def _cycles_report(
    cycles: int, states: list[DriveState], edges: list[tuple[float, int, int, bool]]
) -> str:
    last = states[-1] if states else None
    return (
        f"level control paused and resumed {cycles} times; drive states seen: "
        f"{sorted({m.state for m in states})}; edges per sensor (on, off): "
        f"{[[e[3] for e in edges if e[1] == k].count(on) for k in (0, 1) for on in (1, 0)]}; "
        f"last: state {last and last.state}, level {last and last.level_state} "
        f"{last and list(last.level_sensors)}, {last and last.pause_reason!r}, "
        f"fault {last and last.fault_reason!r}; edges "
        f"{[(round(t - edges[0][0], 1), k, p, on) for t, k, p, on in edges][:60]}"
    )


@pytest.mark.timeout(240)
def test_level_control_pauses_on_a_full_track_resumes_and_times_out_without_parts(
    tmp_path: Path,
) -> None:
    """A stopper at the track's end, 16 touching parts on the track, a robot (the test) picking
    a part every 0.7 s while the feeder waits. Slots of 1 cm from the stopper at 0.2 m: the full
    sensor at 0.165 m is covered from 4 parts queued, the low one at 0.185 m is free below 2 (a
    part passing a sensor covers it for up to 2-3 s: the off delay is longer). The drive must
    pause on the full sensor (within its off delay and the ramp), resume when the low one has
    cleared, and, once every part is picked, fault on the sensors' time-out while feeding."""
    off_delay, on_delay = 4.0, 0.5
    simulator = {
        "track_end": "stopper",
        "pick_interval_s": 0.0,  # the test is the robot: it picks while the feeder waits
        "feed_interval_s": 0.0,  # a finite supply (the bowl-fed cell: the next test)
        "initial_parts": 16,  # touching, 0 .. 0.16 m
        "part_spacing_m": 0.01,
        "sensor_positions_m": "0.165, 0.185",  # sorted: index 0 upstream
    }
    drive = {
        "level": {
            "mode": "two_sensors",
            "low_sensor_index": 1,
            "full_sensor_index": 0,
            "off_delay_s": off_delay,
            "on_delay_s": on_delay,
            "sensor_timeout_s": 15.0,
        }
    }
    namespace = "/feed_level/feeder"
    with feeding_cell(tmp_path, namespace, simulator, drive) as (probe, wire, controller, _):
        assert controller.start(wait_s=30.0)
        pauses = 0
        deadline = time.monotonic() + 150.0
        while time.monotonic() < deadline and pauses < 1:
            with wire.lock:
                states = [m for _, m in wire.states]
            if states and states[-1].state == DriveState.STATE_PAUSED:  # the robot takes a part
                call(probe, Trigger, f"{namespace}/platform_simulator/pick_part", Trigger.Request())
            pauses = _level_cycles(states)
            time.sleep(0.7)
        with wire.lock:
            states = [m for _, m in wire.states]
            edges = list(wire.edges)
        assert pauses >= 1, _cycles_report(pauses, states, edges)
        _check_level_cycles(states, edges, off_delay, on_delay)

        # no part left: the sensors stay unchanged while feeding, a latched fault with the reason
        assert wait_until(lambda: wire.last_state().state == DriveState.STATE_FAULT, 40.0), (
            wire.last_state()
        )
        last = wire.last_state()
        assert last.level_state == DriveState.LEVEL_FAULT
        assert "sensor time-out" in last.fault_reason
        assert "unchanged for 15.0 s while feeding" in last.fault_reason


@dataclass
class TrackWatch:
    """The simulator's parts/state and diagnostics, reduced as they arrive (50 Hz parts/state)."""

    band_m: tuple[float, float]  # (full sensor, low sensor)
    part_length_m: float
    lock: threading.Lock = field(default_factory=threading.Lock)
    most_between: int = 0  # parts over the band between the sensors, at most
    most_on_track: int = 0
    status: dict[str, str] = field(default_factory=dict)  # the latest simulation diagnostics
    most_queued: int = 0

    def on_parts(self, message: PartStateArray) -> None:
        fronts = [p.position_m for p in message.parts if p.on_track]
        full, low = self.band_m
        between = sum(1 for x in fronts if x >= full and x - self.part_length_m <= low)
        with self.lock:
            self.most_between = max(self.most_between, between)
            self.most_on_track = max(self.most_on_track, len(fronts))

    def on_diagnostics(self, message: DiagnosticArray, name: str) -> None:
        for status in message.status:
            if status.name == f"{name}: simulation":
                values = {v.key: v.value for v in status.values}
                with self.lock:
                    self.status = values
                    self.most_queued = max(self.most_queued, int(values["parts_queued"]))


@pytest.mark.timeout(240)
def test_level_control_cycles_a_bowl_fed_track_between_its_sensors(tmp_path: Path) -> None:
    """Issue 34: level control cycles the feeder on and off, keeping the track between the
    sensors. Parts 5 mm long move about 7 mm/s; a bowl feeds one every 1.5 s (10.5 mm apart) and
    a robot at the stopper picks one every 2 s: more come in than go out, so the queue grows while
    the drive feeds and shrinks while it is paused. The track starts with such a stream (9 parts
    10.5 mm apart from the start). Stopper at 0.1 m, slots of 5 mm: the full sensor at 0.0875 m
    (slot 2) is covered from 3 parts queued, the low one at 0.0925 m (slot 1) is free below 2.
    Over the band between the sensors (0.0875 .. 0.0925 m) stand at most 2 parts: the parts in
    slots 1 and 2 (a moving part reaches the band only with at most one queued).

    A stream joins a queue fast: each part stops a part length short of where the one before
    stopped, so parts 10.5 mm apart join every (10.5 - 5) mm / 7 mm/s = 0.8 s, and the queue
    overshoots the full sensor by a part or two during the off delay and the ramp (1 cm parts
    fed 1.05 cm apart joined one after the other within them: the queue ran back to the bowl).
    A passing part covers a sensor for about 0.7 s (1.3 s from rest): the off delay (2 s) is
    longer, so only a queued part pauses the drive.

    The drive must pause and resume at least 3 times, each pause within the off delay and the
    ramp of the full sensor's covering edge (the output at zero while paused), each resume after
    the low sensor was free for the on delay; the queue never reaches the track's start (no feed
    skipped on a full track); while paused, the bowl's exit is blocked (feeds skipped)."""
    off_delay, on_delay = 2.0, 0.5
    full_m, low_m, length_m = 0.0875, 0.0925, 0.005
    simulator = {
        "track_end": "stopper",
        "track_length_m": 0.1,
        "feed_interval_s": 1.5,
        "pick_interval_s": 2.0,
        "initial_parts": 9,
        "part_spacing_m": 0.0105,
        "part_length_m": length_m,
        "sensor_positions_m": f"{full_m}, {low_m}",  # sorted: index 0 (full) upstream
    }
    drive = {
        "level": {
            "mode": "two_sensors",
            "low_sensor_index": 1,
            "full_sensor_index": 0,
            "off_delay_s": off_delay,
            "on_delay_s": on_delay,
            "sensor_timeout_s": 20.0,
        }
    }
    namespace = "/feed_cycles/feeder"
    with feeding_cell(tmp_path, namespace, simulator, drive) as (probe, wire, controller, _):
        watch = TrackWatch((full_m, low_m), length_m)
        probe.create_subscription(PartStateArray, f"{namespace}/parts/state", watch.on_parts, 100)
        probe.create_subscription(
            DiagnosticArray,
            "/diagnostics",
            lambda m: watch.on_diagnostics(m, f"{namespace}/platform_simulator"),
            10,
        )
        started = time.monotonic()
        assert controller.start(wait_s=30.0)
        cycles, states = 0, []
        while time.monotonic() < started + 150.0 and cycles < 3:
            time.sleep(0.5)
            with wire.lock:
                states = [m for _, m in wire.states]
            cycles = _level_cycles(states)
        elapsed = time.monotonic() - started
        with wire.lock:
            states = [m for _, m in wire.states]
            edges = list(wire.edges)
        assert cycles >= 3, _cycles_report(cycles, states, edges)
        measured = _check_level_cycles(states, edges, off_delay, on_delay)
        assert len(measured.pause_delays_s) >= 3  # every pause from a covered full sensor
        assert wait_until(lambda: bool(watch.status), 5.0), "no simulation diagnostics"
        with watch.lock:
            status = dict(watch.status)
            most_between, most_queued = watch.most_between, watch.most_queued
            most_on_track = watch.most_on_track
        print(
            f"{cycles} cycles in {elapsed:.1f} s; pause delays "
            f"{[round(d, 2) for d in measured.pause_delays_s]} s (limit "
            f"{off_delay + STOP_RAMP_S + 0.3:.1f}), resume waits "
            f"{[round(w, 2) for w in measured.resume_waits_s]} s; most queued {most_queued}, "
            f"between the sensors {most_between}, on the track {most_on_track}; {status}"
        )
        assert status["feeds_skipped_track_full"] == "0"  # the queue never reached the start
        assert int(status["feeds_skipped_start_blocked"]) > 0  # the bowl waited while paused
        assert most_between <= 2
