#!/usr/bin/env python3
"""Parts on request: the ``feed_parts`` action against running continuously (issue 34).

Issue 34's target: "``feed_parts`` on the demo feeder: every requested part delivered, the feeder
stopped within one ramp time of the last; time per part reported against running continuously."

The demo feeder as processes over real DDS (its own ``ROS_DOMAIN_ID``, localhost discovery): the
platform simulator (config/cell.yaml's feeder: section ``platform_simulator_mismatched`` plus the
cell's overrides) and the drive interface (the cell's parameters; the speed table and the speed
trim off, which a plain ``set_drive`` does not use), driven by an in-process cell controller (the
example's, with its heartbeat) at the demo's operating point before its ``feed_parts`` step:
``set_target_speed(8 mm/s)`` chooses 30 Hz / 65.70 % from the cell's speed table, sent here as a
plain ``set_drive`` (ramp time 0: the amplitude rate limit makes it 1.314 s, as in the demo).

Parts are counted as ``feed_parts`` counts them: falling edges of sensor 1 on
``parts/sensor_events`` (a part has passed the sensor). The supply is the same for every phase: the
simulator is reset before each (``~/reset``) to a row of parts at the spacing the demo's bowl gives
at this speed (its 1.5 s feed interval x the table's 8 mm/s = 12 mm; parts 10 mm long), the lead
part one spacing behind a part that has just passed sensor 1; the bowl itself is off (stopped, it
would put parts on top of each other at the track's start). On an open track the part rate running
continuously is speed / spacing, which this row makes the demo's bowl-fed rate; no phase needs more
parts than the row holds.

1. Baseline: running continuously, the mean time between parts passing sensor 1 from the first
   part on (10 intervals; ``--quick``: 4).
2. ``feed_parts``: K single-part goals one after another, as a robot asking for the next part
   (K = 6; quick 3), then (fresh row) one goal of N parts (N = 6; quick 3). Every goal must end
   SUCCEEDED with ``parts_delivered`` = the request and exactly that many falling edges on the wire
   between the request and the result (none after it), and the first ``drive/state`` with the
   output at zero must come within the stop ramp (amplitude / ``max_amplitude_rate_percent_per_s``)
   + one drive tick (0.02 s) + 0.1 s transport slack of the last counted edge (both by their
   stamps). Time per part: the result's ``elapsed_s`` / parts (goal accepted to the last part
   passing), and request to result (what the robot waits, the stop ramp included).

Run: ``python bench/bench_feed_parts.py [--quick] [--output FILE.md]``; exit status 1 when a verdict
fails (or a phase could not be measured).
"""

from __future__ import annotations

import argparse
import ctypes
import itertools
import math
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

BIN = Path(sys.executable).parent
CONFIG = Path(__file__).resolve().parents[1] / "config"
NAMESPACE = "/bench_feed_parts/feeder_1"
SENSOR = 1  # the counting sensor, as the example controller's feed_parts step uses
# the demo's operating point before feed_parts: set_target_speed(8 mm/s) on the cell's speed table
FREQUENCY_HZ = 30.0
AMPLITUDE_PERCENT = 65.70
TABLE_SPEED_MPS = 0.008  # the speed the table predicts there (the demo's target)
DRIVE_TICK_S = 0.02  # the drive interface's publish_rate_hz 50
TRANSPORT_SLACK_S = 0.1
STARVATION_S = 20.0
SETTLE_S = 2.0  # after a phase's last goal: any part passing once the feeder is off shows here
PER_PART_TIMEOUT_S = 10.0  # a phase's time-out: 30 s + this per part (a part takes about 1.5 s)


def _die_with_parent() -> None:  # in the child between fork and exec: nothing outlives the bench
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


class Child:
    """A node process; its output goes to a log file (never an unread pipe)."""

    def __init__(self, name: str, command: Sequence[str], log: Path) -> None:
        self.name = name
        self.log = log
        self._file = log.open("wb")
        self.process = subprocess.Popen(
            list(command),
            stdout=self._file,
            stderr=subprocess.STDOUT,
            preexec_fn=_die_with_parent,
        )

    def stop(self) -> str:
        """Ctrl-C, then kill after 15 s; '' or what went wrong."""
        problem = ""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
        try:
            self.process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            problem = f"{self.name} did not stop on Ctrl-C within 15 s: killed"
        self._file.close()
        return problem

    def tail(self, chars: int = 3000) -> str:
        return self.log.read_text(encoding="utf-8", errors="replace")[-chars:]


@dataclass
class Wire:
    """What the probe heard: sensor edges and drive states, by their stamps."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    edges: list[tuple[float, int, int, bool]] = field(default_factory=list)  # t, sensor, id, on
    received: dict[float, float] = field(default_factory=dict)  # edge stamp -> receive time
    states: list[tuple[float, int, float]] = field(default_factory=list)  # t, state, amplitude %

    def on_edge(self, message: Any) -> None:
        stamp = _stamp(message)
        with self.lock:
            self.edges.append((stamp, message.sensor_index, message.part_id, message.present))
            self.received[stamp] = time.time()  # the ROS clock is the system clock here

    def on_state(self, message: Any) -> None:
        with self.lock:
            self.states.append((_stamp(message), message.state, message.amplitude_percent))

    def edge_times(self, present: bool, start: float, end: float = math.inf) -> list[float]:
        """Stamps of sensor SENSOR's rising (``present``) or falling edges in [start, end)."""
        with self.lock:
            return sorted(
                t
                for t, s, _, on in self.edges
                if s == SENSOR and on == present and start <= t < end
            )

    def last_state(self) -> int | None:
        with self.lock:
            return self.states[-1][1] if self.states else None

    def ramp_down_after(self, t_s: float) -> float:
        """Stamp of the first drive/state after ``t_s`` with less output than the one before."""
        with self.lock:
            previous = math.inf
            for stamp, _, amplitude in self.states:
                if stamp >= t_s and amplitude < previous:
                    return stamp
                previous = amplitude
        return math.nan

    def first_zero_after(self, t_s: float) -> float:
        """Stamp of the first drive/state after ``t_s`` with the output at zero (or idle)."""
        from feeder_ros.msg import DriveState

        with self.lock:
            for stamp, state, amplitude in self.states:
                if stamp >= t_s and (amplitude == 0.0 or state == DriveState.STATE_IDLE):
                    return stamp
        return math.nan


def _stamp(message: Any) -> float:
    return float(message.header.stamp.sec) + float(message.header.stamp.nanosec) * 1e-9


def wait_until(predicate: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def _await(future: Any, timeout_s: float, what: str) -> Any:
    if not wait_until(future.done, timeout_s):
        raise RuntimeError(f"{what}: no answer within {timeout_s:g} s")
    return future.result()


@dataclass(frozen=True)
class Supply:
    """A row of parts put down by the simulator's reset (initial_parts), bowl off."""

    count: int
    spacing_m: float
    start_m: float
    lead_m: float


def supply_row(sensor_m: float, part_length_m: float, spacing_m: float) -> Supply:
    """The longest row from the track's start whose lead part is one spacing behind a part that
    has just passed the sensor (its rear at the sensor): lead front at sensor + length - spacing."""
    lead = sensor_m + part_length_m - spacing_m
    count = math.floor(lead / spacing_m + 1e-9) + 1
    return Supply(count, spacing_m, lead - (count - 1) * spacing_m, lead)


def cell_files(
    workdir: Path, supply: Supply, drive: dict[str, Any]
) -> tuple[list[tuple[str, list[str]]], dict[str, Any], dict[str, Any]]:
    """The demo feeder's simulator and drive interface (config/cell.yaml) with the bench's
    supply; returns their command lines and (simulator, drive) parameters."""
    from feeder_ros.cell import load_cell, parameters_document
    from feeder_ros.cli.cell import node_executables

    tree = yaml.safe_load((CONFIG / "cell.yaml").read_text(encoding="utf-8"))
    feeder = tree["cell"]["feeders"][0]
    feeder["namespace"] = NAMESPACE
    nodes = feeder["nodes"]
    for name in [n for n in nodes if n not in ("platform_simulator", "drive_interface")]:
        del nodes[name]
    for spec in nodes.values():
        if "params_file" in spec:
            spec["params_file"] = str(CONFIG / spec["params_file"])
    nodes["platform_simulator"].setdefault("parameters", {}).update(
        {
            "initial_parts": supply.count,
            "part_spacing_m": supply.spacing_m,
            "part_start_m": supply.start_m,
            "feed_interval_s": 0.0,
        }
    )
    nodes["drive_interface"].setdefault("parameters", {}).update(drive)
    path = workdir / "cell.yaml"
    path.write_text(yaml.safe_dump(tree), encoding="utf-8")
    cell = load_cell(path, node_executables())
    parameters = workdir / "parameters.yaml"
    parameters.write_text(parameters_document(cell), encoding="utf-8")
    values = {launch.executable: dict(launch.parameters) for launch in cell.nodes}
    commands = [
        (launch.executable, [str(BIN / launch.executable), *launch.ros_arguments(parameters)])
        for launch in cell.nodes
    ]
    return commands, values["platform_simulator"], values["drive_interface"]


def demo_simulator() -> dict[str, Any]:
    """The demo cell's simulator parameters, as config/cell.yaml gives them."""
    from feeder_ros.cell import load_cell

    cell = load_cell(CONFIG / "cell.yaml")
    return next(dict(n.parameters) for n in cell.nodes if n.executable == "platform_simulator")


@contextmanager
def probe() -> Iterator[Any]:
    """An rclpy node in its own context, spun by a background thread."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("bench_feed_parts_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stopping = threading.Event()
    errors: list[BaseException] = []

    def spin() -> None:
        try:
            executor.spin()
        except BaseException as error:  # rclpy can trip over its own shutdown: only then ignored
            if not stopping.is_set():
                errors.append(error)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield node
    finally:
        stopping.set()
        executor.shutdown()
        thread.join(timeout=5)
        node.destroy_node()
        rclpy.shutdown(context=context)
    if errors:
        raise RuntimeError(f"the probe's executor thread died: {errors[0]!r}")


def _now(node: Any) -> float:
    return float(node.get_clock().now().nanoseconds) * 1e-9


@dataclass
class GoalRun:
    requested: int
    sent_s: float
    result_s: float = math.nan
    outcome: int = -1
    reason: str = ""
    delivered: int = 0
    elapsed_s: float = math.nan
    time_per_part_s: float = math.nan
    passed: list[float] = field(default_factory=list)  # falling edges, request to result
    arrived: int = 0  # rising edges, request to result (a part can arrive in one goal's stop
    # ramp and pass in the next goal: these need not equal the request)
    after: int = 0  # falling edges after the result, before the next request (or SETTLE_S)
    stop_s: float = math.nan  # last counted edge to the first drive/state with the output off
    # where the stop's time went: the edge's arrival at the probe after its stamp (the
    # simulator's lag and DDS), the first drive/state with less output after the edge
    edge_late_s: float = math.nan
    ramp_down_s: float = math.nan

    @property
    def succeeded(self) -> bool:
        from feeder_ros.action import FeedParts

        return bool(self.outcome == FeedParts.Result.OUTCOME_SUCCEEDED)


class Bench:
    """The processes, the probe, the controller and the action client."""

    def __init__(self, node: Any, wire: Wire, controller: Any) -> None:
        from rclpy.action.client import ActionClient
        from std_srvs.srv import Trigger

        from feeder_ros.action import FeedParts

        self.node = node
        self.wire = wire
        self.controller = controller
        self.client = ActionClient(node, FeedParts, f"{NAMESPACE}/feed_parts")
        self.reset_client = node.create_client(Trigger, f"{NAMESPACE}/platform_simulator/reset")

    def reset_simulator(self) -> None:
        """A fresh row of parts (the drive is idle: nothing moves)."""
        from std_srvs.srv import Trigger

        if not self.reset_client.wait_for_service(timeout_sec=30.0):
            raise RuntimeError("the simulator's ~/reset is not available")
        answer = _await(self.reset_client.call_async(Trigger.Request()), 30.0, "~/reset")
        if not answer.success:
            raise RuntimeError(f"~/reset: {answer.message}")
        time.sleep(0.5)  # anything the reset put on the wire has arrived

    def wait_idle(self, timeout_s: float = 30.0) -> None:
        from feeder_ros.msg import DriveState

        if not wait_until(lambda: self.wire.last_state() == DriveState.STATE_IDLE, timeout_s):
            raise RuntimeError(f"the drive was not idle within {timeout_s:g} s")

    def continuous(self, parts: int, timeout_s: float) -> tuple[float, list[float]]:
        """Run continuously until ``parts`` parts have passed the sensor: the time of the start
        request and the parts' edge stamps."""
        self.reset_simulator()
        start = _now(self.node)
        if not self.controller.start(wait_s=30.0):
            raise RuntimeError("start refused")
        try:
            if not wait_until(lambda: len(self.wire.edge_times(False, start)) >= parts, timeout_s):
                got = len(self.wire.edge_times(False, start))
                raise RuntimeError(f"continuous running: {got} of {parts} parts in {timeout_s} s")
        finally:
            self.controller.trigger("stop")
            self.wait_idle()
        return start, self.wire.edge_times(False, start)[:parts]

    def goals(self, counts: Sequence[int], timeout_s: float) -> list[GoalRun]:
        """feed_parts goals one after another (each sent when the one before has its result)."""
        from feeder_ros.action import FeedParts

        self.reset_simulator()
        runs: list[GoalRun] = []
        for count in counts:
            run = GoalRun(count, _now(self.node))
            runs.append(run)
            goal = FeedParts.Goal(
                mode=FeedParts.Goal.MODE_COUNT,
                part_count=count,
                sensor_index=SENSOR,
                starvation_timeout_s=STARVATION_S,
            )
            handle = _await(self.client.send_goal_async(goal), 30.0, "feed_parts goal")
            if not handle.accepted:
                run.reason = "goal rejected"
                break
            future = handle.get_result_async()
            answered: list[float] = []  # when the result arrived (the executor thread's callback)

            def arrived(_future: Any, at: list[float] = answered) -> None:
                at.append(_now(self.node))

            future.add_done_callback(arrived)
            result = _await(future, timeout_s, "feed_parts result").result
            for _ in range(50):  # (the callback runs just after the future is done)
                if answered:
                    break
                time.sleep(0.02)
            run.result_s = answered[0] if answered else _now(self.node)
            run.outcome = result.outcome
            run.reason = result.reason
            run.delivered = result.parts_delivered
            run.elapsed_s = result.elapsed_s
            run.time_per_part_s = result.time_per_part_s
            if not run.succeeded:
                break
        time.sleep(SETTLE_S)
        self.wait_idle()
        for k, run in enumerate(runs):
            end = run.result_s if math.isfinite(run.result_s) else _now(self.node)
            following = runs[k + 1].sent_s if k + 1 < len(runs) else end + SETTLE_S
            run.passed = self.wire.edge_times(False, run.sent_s, end)
            run.arrived = len(self.wire.edge_times(True, run.sent_s, end))
            run.after = len(self.wire.edge_times(False, end, following))
            if run.passed:
                last = run.passed[min(run.requested, len(run.passed)) - 1]
                run.stop_s = self.wire.first_zero_after(last) - last
                run.edge_late_s = self.wire.received.get(last, math.nan) - last
                run.ramp_down_s = self.wire.ramp_down_after(last) - last
        return runs


def measure(
    baseline_parts: int, singles: int, batch: int, supply: Supply, workdir: Path
) -> dict[str, Any]:
    from feeder_ros.examples.cell_controller import CellController
    from feeder_ros.msg import DriveState, PartSensorEvent
    from feeder_ros.srv import SetDrive

    drive_overrides = {"speed_model_enabled": False, "speed_trim": {"enabled": False}}
    commands, simulator, drive = cell_files(workdir, supply, drive_overrides)
    children = [Child(name, command, workdir / f"{name}.log") for name, command in commands]
    wire = Wire()
    failed = True
    try:
        with probe() as node:
            node.create_subscription(
                PartSensorEvent, f"{NAMESPACE}/parts/sensor_events", wire.on_edge, 100
            )
            node.create_subscription(DriveState, f"{NAMESPACE}/drive/state", wire.on_state, 100)
            controller = CellController(NAMESPACE, context=node.context)
            executor = node.executor
            assert executor is not None
            executor.add_node(controller)
            try:
                bench = Bench(node, wire, controller)
                controller.bring_up()
                answer = controller.call(
                    SetDrive,
                    "set_drive",
                    SetDrive.Request(
                        frequency_hz=FREQUENCY_HZ,
                        amplitude_percent=AMPLITUDE_PERCENT,
                        ramp_time_s=0.0,
                    ),
                )
                if answer.result == SetDrive.Response.REFUSED:
                    raise RuntimeError(f"set_drive refused: {answer.reason}")
                if not bench.client.wait_for_server(timeout_sec=30.0):
                    raise RuntimeError("feed_parts is not available")
                # the drive has heard the heartbeat once it starts (the topic is discovered
                # after start-up): start, then stop at once (the reset puts the parts back)
                if not controller.start(wait_s=30.0) or not controller.trigger("stop"):
                    raise RuntimeError("the drive did not start")
                bench.wait_idle()
                stop_ramp_s = answer.amplitude_percent / float(
                    drive["max_amplitude_rate_percent_per_s"]
                )
                started = time.perf_counter()
                start, edges = bench.continuous(
                    baseline_parts + 1, 30.0 + PER_PART_TIMEOUT_S * baseline_parts
                )
                single_runs = bench.goals([1] * singles, 60.0)
                batch_runs = bench.goals([batch], 30.0 + PER_PART_TIMEOUT_S * batch)
                wall = time.perf_counter() - started
            finally:
                executor.remove_node(controller)
                controller.destroy_node()
        failed = False
    finally:
        problems = [problem for child in children if (problem := child.stop())]
        if failed or problems:
            for child in children:
                print(f"--- {child.name} (exit {child.process.returncode}):\n{child.tail()}")
        if problems:
            print("\n".join(problems))
    return {
        "answer": answer,
        "stop_ramp_s": stop_ramp_s,
        "edges": edges,
        "first_part_s": edges[0] - start,
        "singles": single_runs,
        "batch": batch_runs,
        "wall_s": wall,
        "simulator": simulator,
    }


def _goal_rows(label: str, runs: Sequence[GoalRun], limit_s: float) -> list[str]:
    from feeder_ros.action import FeedParts

    names = {
        getattr(FeedParts.Result, n): n.removeprefix("OUTCOME_").lower()
        for n in dir(FeedParts.Result)
        if n.startswith("OUTCOME_")
    }
    rows = []
    for k, run in enumerate(runs, 1):
        rows.append(
            f"| {label} {k} | {run.requested} | {names.get(run.outcome, '?')} | {run.delivered} | "
            f"{len(run.passed)} | {run.after} | {run.arrived} | {run.elapsed_s:.2f} | "
            f"{run.result_s - run.sent_s:.2f} | {run.stop_s:.3f} "
            f"({'ok' if run.stop_s <= limit_s else 'LATE'}) | {run.edge_late_s:.3f} | "
            f"{run.ramp_down_s:.3f} |"
        )
    return rows


def report(data: dict[str, Any], supply: Supply, quick: bool) -> tuple[str, bool]:
    edges: list[float] = data["edges"]
    singles: list[GoalRun] = data["singles"]
    batch: list[GoalRun] = data["batch"]
    ramp = data["stop_ramp_s"]
    limit = ramp + DRIVE_TICK_S + TRANSPORT_SLACK_S
    intervals = [b - a for a, b in itertools.pairwise(edges)]
    base = (edges[-1] - edges[0]) / len(intervals)
    runs = singles + batch

    def per_part(group: Sequence[GoalRun], kind: str) -> float:
        parts = sum(r.delivered for r in group)
        if kind == "elapsed":
            total = sum(r.elapsed_s for r in group)
        else:
            total = sum(r.result_s - r.sent_s for r in group)
        return total / parts if parts else math.nan

    requested = sum(r.requested for r in runs)
    delivered = sum(r.delivered for r in runs)
    on_wire = sum(len(r.passed) for r in runs)
    after = sum(r.after for r in runs)
    every = (
        len(singles) == data["singles_asked"]
        and len(batch) == 1
        and all(r.succeeded and r.delivered == r.requested == len(r.passed) for r in runs)
        and after == 0
    )
    stops = [r.stop_s for r in runs]
    worst = max(stops) if stops and all(math.isfinite(s) for s in stops) else math.nan
    stopped = math.isfinite(worst) and worst <= limit
    answer = data["answer"]
    simulator = data["simulator"]
    k, n = data["singles_asked"], batch[0].requested if batch else 0
    rows = [
        ("running continuously (baseline): mean interval, parts 1 .. "
         f"{len(edges)} past sensor {SENSOR}", f"{len(intervals)} intervals", base),
        (f"feed_parts, {k} single-part goals one after another: elapsed_s / part",
         f"{sum(r.delivered for r in singles)}", per_part(singles, "elapsed")),
        ("... request to result (what the robot waits: the stop ramp included)",
         f"{sum(r.delivered for r in singles)}", per_part(singles, "round trip")),
        (f"... goals 2 .. {k} only (the next part moved up in the stop ramp before): "
         "elapsed_s / part", f"{sum(r.delivered for r in singles[1:])}",
         per_part(singles[1:], "elapsed")),
        (f"... goals 2 .. {k} only: request to result",
         f"{sum(r.delivered for r in singles[1:])}", per_part(singles[1:], "round trip")),
        (f"feed_parts, one goal of {n} parts: elapsed_s / part",
         f"{sum(r.delivered for r in batch)}", per_part(batch, "elapsed")),
        ("... request to result",
         f"{sum(r.delivered for r in batch)}", per_part(batch, "round trip")),
    ]  # fmt: skip
    title = "### Parts on request: `feed_parts` against running continuously"
    lines = [
        title + (" (quick)" if quick else ""),
        "",
        "The demo feeder of config/cell.yaml (the `platform_simulator_mismatched` plant, "
        f"sensors at {simulator['sensor_positions_m']} m) and its drive interface as processes "
        "over DDS, driven by `set_drive` "
        f"{answer.frequency_hz:g} Hz / {answer.amplitude_percent:.2f} % (the demo's "
        "`set_target_speed(8 mm/s)` point); parts counted on sensor "
        f"{SENSOR} (falling edges: a part has passed). Supply before each phase: a row of "
        f"{supply.count} parts {supply.spacing_m * 1e3:.1f} mm apart (10 mm long; the demo bowl's "
        f"{data['bowl_interval_s']:g} s x the table's 8 mm/s), lead part "
        "one spacing behind a part just past the sensor; bowl off. Running continuously "
        "on an open track delivers speed / spacing: with this row, the demo's bowl-fed rate; "
        f"no phase ran short of parts. Stop ramp {ramp:.3f} s "
        f"({answer.amplitude_percent:.2f} % at the amplitude rate limit); limit {limit:.3f} s "
        f"(+ {DRIVE_TICK_S:g} s drive tick + {TRANSPORT_SLACK_S:g} s transport). "
        f"Wall time {data['wall_s']:.0f} s.",
        "",
        "| measurement | parts | s per part | ratio vs continuous |",
        "|---|---:|---:|---:|",
        *[
            f"| {name} | {count} | {value:.3f} | {value / base:.2f} |"
            for name, count, value in rows
        ],
        f"| delivered / requested (results; falling edges on the wire; passed after a result) | "
        f"{requested} | {delivered} / {requested}; {on_wire} / {requested}; {after} | |",
        f"| worst stop: last counted part to the first `drive/state` at zero output | "
        f"{len(stops)} goals | {worst:.3f} s (ramp {ramp:.3f} s, limit {limit:.3f} s) | "
        f"{worst / ramp:.3f} ramps |",
        "",
        f"Continuous: intervals {min(intervals):.3f} .. {max(intervals):.3f} s (implied part "
        f"speed {supply.spacing_m / base * 1e3:.2f} mm/s); the first part passed "
        f"{data['first_part_s']:.2f} s after the start request (a fresh row, as for the first "
        "single-part goal). Rising edges (a part reaching the sensor) are not the count: the "
        "next part can arrive during a goal's stop ramp and pass in the next goal.",
        "",
        "| goal | asked | outcome | parts_delivered | passed (wire) | passed after result | "
        "arrived (rising edges) | elapsed_s | request to result [s] | stop [s] | "
        "edge on the wire after its stamp [s] | first lower output after the edge [s] |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        *_goal_rows("single", singles, limit),
        *_goal_rows(f"{n}-part", batch, limit),
        "",
        f"- every requested part delivered (SUCCEEDED, parts_delivered = request = falling edges "
        f"on the wire, none after the result): {'PASS' if every else 'FAIL'} ({delivered} / "
        f"{requested} by the results, {on_wire} / {requested} on the wire, {after} after)",
        f"- stopped within one ramp time of the last part (<= {ramp:.3f} s ramp + "
        f"{DRIVE_TICK_S:g} s + {TRANSPORT_SLACK_S:g} s): {'PASS' if stopped else 'FAIL'} "
        f"(worst {worst:.3f} s)",
    ]
    failures = [r for r in runs if not r.succeeded]
    if failures:
        lines.append(f"- goals that did not succeed: {'; '.join(r.reason for r in failures)}")
    return "\n".join(lines), every and stopped


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="3 single goals, a 3-part goal")
    parser.add_argument("--output", type=Path, help="write the markdown table here")
    parser.add_argument("--domain-id", type=int, help="ROS_DOMAIN_ID (default: random 150-200)")
    args = parser.parse_args()
    if shutil.which("platform_simulator", path=str(BIN)) is None:
        print("platform_simulator is not installed in this venv: run `make install`")
        return 2
    domain = args.domain_id if args.domain_id is not None else random.randint(150, 200)
    os.environ["ROS_DOMAIN_ID"] = str(domain)  # the probe's context and the children read it
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    for number in (signal.SIGINT, signal.SIGTERM):  # the children are stopped as on Ctrl-C
        signal.signal(number, signal.default_int_handler)
    baseline_parts, singles, batch = (4, 3, 3) if args.quick else (10, 6, 6)
    demo = demo_simulator()
    sensor_m = float(str(demo["sensor_positions_m"]).split(",")[SENSOR])
    spacing = round(demo["feed_interval_s"] * TABLE_SPEED_MPS, 6)
    supply = supply_row(sensor_m, float(demo.get("part_length_m", 0.01)), spacing)
    needed = max(baseline_parts + 1, singles, batch)
    if supply.count < needed:
        print(f"the row holds {supply.count} parts, the bench needs {needed}")
        return 2
    print(f"ROS_DOMAIN_ID={domain}; supply {supply}", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_feed_parts_") as workdir:
        try:
            data = measure(baseline_parts, singles, batch, supply, Path(workdir))
        except RuntimeError as error:
            print(f"FAIL: {error}")
            return 1
        except KeyboardInterrupt:
            print("interrupted: the nodes were stopped")
            return 130
    data["singles_asked"] = singles
    data["bowl_interval_s"] = demo["feed_interval_s"]
    text, passed = report(data, supply, args.quick)
    print(text)
    if args.output:
        args.output.write_text(text + "\n", encoding="utf-8")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
