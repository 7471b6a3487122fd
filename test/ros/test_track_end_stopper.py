"""The platform simulator's track-end stopper as a real process over DDS: parts queue at the end of
the track, sit still at their slots (parts/state), cover the part-present sensors and leave the
feeder only when picked, on request (``~/pick_part``) or on the robot's schedule
(``pick_interval_s``); feeds onto a full track are skipped; an open track end refuses picks. A
bowl (either track end) puts no part onto one still at the track's start.

Simulated time at 5x real time (``use_sim_time``: the simulator publishes /clock and stamps
everything on it); the drive is an unstamped command (applied at once) with no command timeout.
"""

from __future__ import annotations

import math
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_test_tools import call, probe_node, running, wait_until
from std_srvs.srv import Trigger

from feeder_ros.msg import CarrierState, DriveCommand, PartExit, PartSensorEvent, PartStateArray

SIMULATOR = str(Path(sys.executable).parent / "platform_simulator")
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
L = 0.01  # part length


def _command(ns: str, *parameters: str, track_end: str = "stopper") -> list[str]:
    arguments = ["-p", "use_sim_time:=true", "-p", "real_time_factor:=5.0"]
    arguments += ["-p", "command_timeout_s:=0.0", "-p", "damping_ns_per_m:=200.0"]
    arguments += ["-p", "imu_rate_hz:=100.0", "-p", "state_rate_hz:=100.0"]
    arguments += ["-p", f"track_end:={track_end}", "-p", f"part_length_m:={L}"]
    for item in parameters:
        arguments += ["-p", item]
    return [SIMULATOR, "--ros-args", "-r", f"__ns:={ns}", *arguments]


def _stamp(message: Any) -> float:
    return message.header.stamp.sec + message.header.stamp.nanosec * 1e-9


@dataclass
class Wire:
    """What the probe heard from one simulator."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    parts: list[PartStateArray] = field(default_factory=list)
    exits: list[PartExit] = field(default_factory=list)
    edges: list[PartSensorEvent] = field(default_factory=list)
    carrier: dict[tuple[int, int], float] = field(default_factory=dict)  # stamp: velocity
    displacement: dict[float, float] = field(default_factory=dict)  # time (s): carrier x (m)
    status: dict[str, str] = field(default_factory=dict)  # the latest simulation diagnostics
    statuses: int = 0

    def listen(self, node: Node, ns: str) -> None:
        def keep(name: str) -> Any:
            def append(message: Any) -> None:
                with self.lock:
                    getattr(self, name).append(message)

            return append

        node.create_subscription(PartStateArray, f"{ns}/parts/state", keep("parts"), RELIABLE)
        node.create_subscription(PartExit, f"{ns}/parts/exit", keep("exits"), RELIABLE)
        node.create_subscription(
            PartSensorEvent, f"{ns}/parts/sensor_events", keep("edges"), RELIABLE
        )
        node.create_subscription(CarrierState, f"{ns}/carrier/state", self._on_state, RELIABLE)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)

    def _on_state(self, message: CarrierState) -> None:
        with self.lock:
            stamp = (message.header.stamp.sec, message.header.stamp.nanosec)
            self.carrier[stamp] = message.velocity_mps
            self.displacement[_stamp(message)] = message.displacement_m

    def _on_diagnostics(self, message: DiagnosticArray) -> None:
        for status in message.status:
            if status.name.endswith(": simulation"):
                with self.lock:
                    self.status = {v.key: v.value for v in status.values}
                    self.statuses += 1

    def latest(self) -> PartStateArray | None:
        with self.lock:
            return self.parts[-1] if self.parts else None

    def on_track(self) -> dict[int, Any]:
        """The parts on the track in the latest parts/state: {id: PartState}."""
        latest = self.latest()
        return {} if latest is None else {p.part_id: p for p in latest.parts if p.on_track}

    def edge_list(self) -> list[tuple[float, int, int, bool]]:
        with self.lock:
            return [(_stamp(e), e.sensor_index, e.part_id, e.present) for e in self.edges]

    def exit_list(self) -> list[tuple[float, int, int]]:
        with self.lock:
            return [(_stamp(e), e.part_id, e.parts_out_total) for e in self.exits]

    def fresh_status(self) -> dict[str, str]:
        """The next simulation status (published at 1 Hz wall time) after now."""
        with self.lock:
            seen = self.statuses
        assert wait_until(lambda: self.statuses > seen, 10.0), "no simulation diagnostics"
        with self.lock:
            return dict(self.status)


def _drive(node: Node, ns: str) -> Any:
    """A publisher of the drive command (20 Hz, 40 N: parts move about 16 mm/s); call it to send."""
    publisher = node.create_publisher(DriveCommand, f"{ns}/drive/command", 10)

    def send() -> None:  # unstamped: applied at once
        publisher.publish(DriveCommand(enabled=True, frequency_hz=20.0, amplitude_n=40.0))

    return send


def _double(name: str, value: float) -> ParameterMsg:
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    )


def test_parts_queue_at_the_stopper_sit_on_the_sensors_and_leave_when_picked() -> None:
    """Three parts (fronts 0, 12, 24 mm) queue at a stopper at 4 cm: the front one (part 2) at
    4 cm, then 3 and 2 cm. Sensors (indices in track order) 0 under slot 1 (2.5 cm) and 1 under
    slot 0 (3.5 cm)."""
    ns = "/stopper_picks"
    command = _command(
        ns,
        "track_length_m:=0.04",
        "initial_parts:=3",
        "part_start_m:=0.0",
        "part_spacing_m:=0.012",
        "sensor_positions_m:=0.025, 0.035",
    )
    with running(command), probe_node() as node:
        wire = Wire()
        wire.listen(node, ns)
        drive = _drive(node, ns)
        slots = {2: 0.04, 1: 0.03, 0: 0.02}

        def queued() -> bool:
            drive()
            parts = wire.on_track()
            return sorted(parts) == [0, 1, 2] and all(
                abs(parts[i].position_m - slot) < 1e-9 for i, slot in slots.items()
            )

        assert wait_until(queued, 60.0), wire.latest()
        # they sit: more simulated time (1.5 s wall: 7.5 s), no exit, no sensor edge
        edges = wire.edge_list()
        stamp_then = _stamp(wire.latest())
        assert wait_until(lambda: _stamp(wire.latest()) > stamp_then + 5.0, 20.0)
        assert wire.exit_list() == []
        assert wire.edge_list() == edges
        # sensor 1 (3.5 cm) covered by part 2, sensor 0 (2.5 cm) by part 1, after part 2 passed
        assert [(s, p, on) for _, s, p, on in edges if s == 1] == [(1, 2, True)]
        assert [(s, p, on) for _, s, p, on in edges if s == 0] == [
            (0, 2, True),
            (0, 2, False),
            (0, 1, True),
        ]
        # standing still on the carrier: the carrier's velocity, relative 0, sticking
        latest = wire.latest()
        assert latest is not None
        for part in latest.parts:
            assert part.phase == part.PHASE_STICK
            assert part.relative_velocity_mps == 0.0
        key = (latest.header.stamp.sec, latest.header.stamp.nanosec)
        assert wait_until(lambda: key in wire.carrier, 10.0)
        assert {p.velocity_mps for p in latest.parts} == {wire.carrier[key]}
        assert wire.carrier[key] != 0.0  # (a driven carrier)
        status = wire.fresh_status()
        assert status["track_end"] == "stopper"
        assert status["parts_queued"] == "3"
        assert status["queue_tail_m"] == "0.01"

        base = f"{ns}/platform_simulator"

        def pick(expected_part: int, exits: int) -> float:
            """Pick, wait for its exit; the exit's stamp (the pick time)."""
            answer = call(node, Trigger, f"{base}/pick_part", Trigger.Request())
            assert answer.success, answer.message
            assert answer.message.startswith(f"picked part {expected_part} at t = ")
            assert wait_until(lambda: len(wire.exit_list()) == exits, 10.0)
            t, part, total = wire.exit_list()[-1]
            assert (part, total) == (expected_part, exits)
            assert float(answer.message.split("t = ")[1].split()[0]) == pytest.approx(t, abs=1e-6)
            later = _stamp(wire.latest())  # let the sensors and parts/state catch up
            assert wait_until(lambda: _stamp(wire.latest()) > later + 1.0, 10.0)
            return t

        def edges_since(t: float) -> list[tuple[float, int, int, bool]]:
            return [e for e in wire.edge_list() if e[0] >= t]

        # pick 1: part 2 leaves; 1 and 0 move up; both sensors stay covered: no edge
        t1 = pick(2, 1)
        assert edges_since(t1) == []
        parts = wire.on_track()
        assert {i: p.position_m for i, p in parts.items()} == pytest.approx({1: 0.04, 0: 0.03})
        with wire.lock:  # part 2 listed once more, off the track, then no longer
            gone = [
                m for m in wire.parts if any(p.part_id == 2 and not p.on_track for p in m.parts)
            ]
            assert len(gone) == 1
            assert _stamp(gone[0]) >= t1
        # pick 2: part 1 leaves; part 0 moves to slot 0: sensor 0 becomes free, at the pick time
        t2 = pick(1, 2)
        assert edges_since(t1 + 1e-9) == [(t2, 0, 0, False)]
        assert {i: p.position_m for i, p in wire.on_track().items()} == pytest.approx({0: 0.04})
        # pick 3: the last part leaves; sensor 1 becomes free
        t3 = pick(0, 3)
        assert edges_since(t2 + 1e-9) == [(t3, 1, 0, False)]
        assert wire.on_track() == {}
        empty = call(node, Trigger, f"{base}/pick_part", Trigger.Request())
        assert not empty.success
        assert empty.message == "no part to pick at the stopper: 0 queued, 0 of them being picked"
        status = wire.fresh_status()
        assert status["parts_queued"] == "0"
        assert status["parts_picked_total"] == "3"
        assert status["parts_out_total"] == "3"
        assert status["queue_tail_m"] == "0.04"


def test_a_robot_picks_periodically_and_feeds_onto_a_full_track_are_skipped() -> None:
    """A 3 cm track takes three queued parts (full at a 0 tail); a bowl feeds every 0.8 s, the
    robot picks every 5 s: one exit per pick, 5 s apart; the sensor under slot 0 covered all the
    while; reset empties the queue."""
    ns = "/stopper_robot"
    command = _command(
        ns,
        "track_length_m:=0.03",
        "initial_parts:=0",
        "part_start_m:=0.0",
        "sensor_positions_m:='0.025'",  # (quoted: a string, not a double)
    )
    with running(command), probe_node() as node:
        wire = Wire()
        wire.listen(node, ns)
        drive = _drive(node, ns)
        base = f"{ns}/platform_simulator"
        # feed and pick from when the carrier moves (parts put down before would pile up at 0)
        assert wait_until(lambda: drive() or bool(wire.carrier), 30.0)
        assert wait_until(lambda: drive() or wire.fresh_status()["drive_amplitude_n"] == "40", 30.0)
        request = SetParameters.Request(
            parameters=[_double("feed_interval_s", 0.8), _double("pick_interval_s", 5.0)]
        )
        results = call(node, SetParameters, f"{base}/set_parameters", request).results
        assert all(r.successful for r in results), results

        assert wait_until(lambda: len(wire.exit_list()) >= 3, 60.0), wire.fresh_status()
        exits = wire.exit_list()[:3]
        assert [(part, total) for _, part, total in exits] == [(0, 1), (1, 2), (2, 3)]
        assert exits[1][0] - exits[0][0] == pytest.approx(5.0, abs=1e-6)
        assert exits[2][0] - exits[1][0] == pytest.approx(5.0, abs=1e-6)
        status = wire.fresh_status()
        assert int(status["feeds_skipped_track_full"]) > 0
        assert status["picks_missed_queue_empty"] == "0"
        assert int(status["parts_picked_total"]) == int(status["parts_out_total"]) >= 3
        with wire.lock:
            states = list(wire.parts)
        on_track = [p for m in states for p in m.parts if p.on_track]
        assert max(p.position_m for p in on_track) <= 0.03 + 1e-12  # none past the stopper
        assert max(sum(p.on_track for p in m.parts) for m in states) <= 4  # 3 queued + 1 moving
        # the sensor under slot 0 went covered once and stayed covered through the picks
        assert [(s, p, on) for _, s, p, on in wire.edge_list()] == [(0, 0, True)]

        reset = call(node, Trigger, f"{base}/reset", Trigger.Request())
        assert reset.success, reset.message
        status = wire.fresh_status()
        assert status["parts_queued"] == "0"
        assert status["parts_picked_total"] == "0"


@pytest.mark.parametrize("track_end", ["stopper", "open"])
def test_a_bowl_puts_no_part_onto_one_at_the_start(track_end: str) -> None:
    """A bowl feeding every 0.1 s onto a track that does not move (no drive yet): one part at the
    start, every other feed skipped (the bowl's exit is blocked) and counted, none on top of it.
    Once the track moves the bowl feeds again, on its interval: each new part is put down a part
    length or more behind the one ahead (16 mm/s: every 0.6-0.7 s, 10-11 mm apart)."""
    ns = f"/bowl_exit_{track_end}"
    start, interval = 0.005, 0.1
    command = _command(
        ns,
        "track_length_m:=0.1",
        "initial_parts:=0",
        f"part_start_m:={start}",
        f"feed_interval_s:={interval}",
        "sensor_positions_m:='0.05'",
        track_end=track_end,
    )
    with running(command), probe_node() as node:
        wire = Wire()
        wire.listen(node, ns)
        assert wait_until(lambda: float(wire.fresh_status()["simulated_time_s"]) >= 5.0, 30.0)
        status = wire.fresh_status()
        with wire.lock:
            still = list(wire.parts)
        assert still, "no parts/state"
        for message in still:  # after the first feed (0.1 s): that part alone, where it was put
            on_track = [p.position_m for p in message.parts if p.on_track]
            assert on_track == ([start] if _stamp(message) > interval + 1e-6 else []), on_track
        # every feed interval tried: the first one fed, all the others skipped
        feeds = int(float(status["simulated_time_s"]) / interval + 1e-6)
        assert abs(int(status["feeds_skipped_start_blocked"]) - (feeds - 1)) <= 1, (feeds, status)
        assert status["parts_on_track"] == "1"
        assert status.get("feeds_skipped_track_full", "0") == "0"  # (stopper: never full)

        drive = _drive(node, ns)
        assert wait_until(lambda: drive() or len(wire.on_track()) >= 4, 60.0), wire.latest()
        with wire.lock:
            states = list(wire.parts)
        first: dict[int, PartStateArray] = {}  # the message that first lists each part
        for message in states:
            for part in message.parts:
                first.setdefault(part.part_id, message)
        fed = sorted(first)
        assert fed == list(range(len(fed))), fed
        # put down on the feed schedule (k * interval: a skipped feed is tried at the next one),
        # first listed at the next parts/state sample (50 Hz) after it
        stamps = [_stamp(first[part]) for part in fed[1:]]
        put = [interval * math.floor(t / interval - 1e-6) for t in stamps]
        assert all(0.0 < t - t_put <= 0.02 + 1e-6 for t, t_put in zip(stamps, put, strict=True)), (
            stamps,
            put,
        )
        with wire.lock:
            t_c, x_c = np.array(sorted(wire.displacement.items())).T
        for part, t, t_put in zip(
            fed[1:], stamps, put, strict=True
        ):  # at the start, clear of every other part
            fronts = {p.part_id: p.position_m for p in first[part].parts if p.on_track}
            # let go at rest in the lab (a bowl's exit): until friction takes it along the track
            # moves under it, so its track position is start - the carrier's displacement since
            # (up to the carrier's stroke), plus at most 1/2 mu g t^2 ~ 0.6 mm of its own in 20 ms
            stroke = float(np.diff(np.interp([t_put, t], t_c, x_c))[0])
            assert fronts[part] + stroke == pytest.approx(start, abs=1e-3), (part, fronts, stroke)
            # the bowl's exit was clear when it let go: every other part a part length away
            before = [m for m in states if abs(_stamp(m) - t_put) < 1e-6]
            assert before, f"no parts/state at the put-down of part {part} ({t_put} s)"
            gaps = [abs(p.position_m - start) for p in before[0].parts if p.on_track]
            assert gaps, f"part {part} put down on an empty track"
            assert min(gaps) >= L - 1e-4, (part, t_put, gaps)
        print(f"{track_end}: parts 1.. first listed at {[round(t, 3) for t in stamps]} s (sim)")


def test_an_open_track_end_refuses_picks() -> None:
    ns = "/stopper_open"
    command = [SIMULATOR, "--ros-args", "-r", f"__ns:={ns}", "-p", "imu_rate_hz:=100.0"]
    with running(command), probe_node() as node:
        wire = Wire()
        wire.listen(node, ns)
        answer = call(node, Trigger, f"{ns}/platform_simulator/pick_part", Trigger.Request())
        assert not answer.success
        assert answer.message == "track_end is open: parts leave at the end of the track"
        status = wire.fresh_status()
        assert status["track_end"] == "open"
        assert "parts_queued" not in status
