"""``make demo``: the simulated feeder cell end to end, on embedded defaults.

1. ``feeder cell`` brings up the cell of ``config/cell.yaml``: the platform simulator (damped
   preset, a bowl feeding a part every 2 s), the vehicle estimator, the drive interface and the
   speed monitor, each a process, in namespace ``/demo_cell/feeder_1``.
2. The example cell controller (``feeder_ros.examples.cell_controller``) drives it through the
   public interface only: start, target speed, change of speed, a watchdog trip (its heartbeat
   stops) and the recovery, three parts asked for with the ``feed_parts`` action, stop.
3. A probe records what the cell published; the demo prints a summary (speeds achieved against
   the targets, by the estimator, by the part-present sensors and in truth; feed rate; diagnostics
   seen) and writes plots and the data to ``--output``.
4. ``feeder record`` records the feeder meanwhile (``--output``/bag), and the demo ends with
   ``feeder analyze``'s report of that bag (``--output``/report/report.html).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from feeder_ros import demo_recording
from feeder_ros.cell import load_cell
from feeder_ros.msg import (
    DriveState,
    PartCalibration,
    PartExit,
    PartStateArray,
    SpeedStatus,
    VehicleEstimate,
)

REPO = Path(__file__).resolve().parents[1]
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
#: the speed monitor's band when the cell file does not set one (its default): "OK at target" is
#: the monitor's claim that the part runs within it, and the demo checks that claim by the truth
DEFAULT_MONITOR_TOLERANCE = 0.05
#: the landing goal after calibration (a benchmark target of the estimator, printed, not judged:
#: the cell promises only what its monitor confirms)
LANDING_GOAL = 0.03
LEVELS = ("OK", "WARN", "ERROR", "STALE")
# how long the cell's nodes may take to appear: a cold start (no bytecode cache, every module
# read from a slow disk) has taken over 50 s on the project's machine type, a warm one 3 s
STARTUP_LIMIT_S = 180.0


def _seconds(stamp: Any) -> float:
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


@dataclass
class Recording:
    """What the probe saw, as rows stamped with the system clock (what ROS time is when the
    simulator runs paced, so part stamps, controller steps and these rows share one time base)."""

    start: float = field(default_factory=time.time)
    #: (time, mean speed, its standard uncertainty, confidence)
    estimate: list[tuple[float, float, float, float]] = field(default_factory=list)
    #: the part calibration as last published (PartCalibration), and when it first was calibrated
    calibration: dict[str, Any] = field(default_factory=dict)
    #: (time, the calibration then): what each phase's estimate rested on
    calibrations: list[tuple[float, dict[str, Any]]] = field(default_factory=list)
    status: list[tuple[float, float, float, float, float, int, int]] = field(default_factory=list)
    drive: list[tuple[float, int, float, float, float]] = field(default_factory=list)
    parts: list[tuple[float, dict[int, float]]] = field(default_factory=list)
    exits: list[float] = field(default_factory=list)
    #: the worst level per diagnostic status name, and the message and time (system clock) it
    #: first came with
    diagnostics: dict[str, int] = field(default_factory=dict)
    diagnostic_messages: dict[str, str] = field(default_factory=dict)
    diagnostic_times: dict[str, float] = field(default_factory=dict)
    #: diagnostics count while the cell runs: its nodes' last statuses while they stop one after
    #: the other (an estimator whose simulator is gone times out) are not the demo's findings
    collecting_diagnostics: bool = True
    lock: threading.Lock = field(default_factory=threading.Lock)

    def now(self) -> float:
        return time.time()

    def note_diagnostic(self, name: str, level: int, message: str, t: float) -> None:
        """Keep a status's worst level and the message and time ``t`` it first came with (under
        ``lock``)."""
        if self.collecting_diagnostics and level > self.diagnostics.get(name, -1):
            self.diagnostics[name] = level
            self.diagnostic_messages[name] = message
            self.diagnostic_times[name] = t

    def add(self, callback: Callable[[Any], None]) -> Callable[[Any], None]:
        def locked(message: Any) -> None:
            with self.lock:
                callback(message)

        return locked


def wait_for_nodes(
    node: Node, expected: Iterable[str], limit_s: float, alive: Callable[[], bool]
) -> list[str]:
    """Wait until every node in ``expected`` (fully qualified names) is in the ROS graph, for
    at most ``limit_s`` or while ``alive()``; returns the ones still missing (sorted)."""
    wanted = set(expected)
    deadline = time.monotonic() + limit_s
    while True:
        present = {
            f"{namespace.rstrip('/')}/{name}"
            for name, namespace in node.get_node_names_and_namespaces()
        }
        missing = sorted(wanted - present)
        if not missing or time.monotonic() >= deadline or not alive():
            return missing
        time.sleep(0.1)


def _probe(namespace: str, recording: Recording) -> tuple[Context, Any, threading.Thread]:
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("demo_probe", context=context)
    r = recording

    def on_estimate(m: VehicleEstimate) -> None:
        r.estimate.append(
            (r.now(), m.mean_speed_mps, m.mean_speed_uncertainty_mps, m.mean_speed_confidence)
        )

    def on_calibration(m: PartCalibration) -> None:
        if m.state != PartCalibration.STATE_NOMINAL and "first_at" not in r.calibration:
            r.calibration["first_at"] = r.now()
        r.calibration.update(
            state=("nominal", "calibrating", "calibrated")[min(m.state, 2)],
            static_friction=round(m.static_friction, 4),
            kinetic_friction=round(m.kinetic_friction, 4),
            accelerometer_gain=round(m.accelerometer_gain, 4),
            transits_used=m.transits_used,
            measurements_refused=m.measurements_refused,
            operating_points=m.operating_points,
        )
        r.calibrations.append((r.now(), calibration_values(m)))

    def on_status(m: SpeedStatus) -> None:
        r.status.append(
            (
                r.now(),
                m.target_speed_mps,
                m.estimated_speed_mps,
                m.transit_speed_mps,
                m.feed_rate_ppm,
                m.level,
                m.alarms,
            )
        )

    def on_drive(m: DriveState) -> None:
        r.drive.append((r.now(), m.state, m.frequency_hz, m.amplitude_percent, m.amplitude_n))

    def on_parts(m: PartStateArray) -> None:
        positions = {p.part_id: p.position_m for p in m.parts if p.on_track}
        r.parts.append((_seconds(m.header.stamp), positions))

    def on_exit(m: PartExit) -> None:
        r.exits.append(r.now())

    def on_diagnostics(m: DiagnosticArray) -> None:
        for status in m.status:
            level = status.level[0] if isinstance(status.level, bytes) else int(status.level)
            r.note_diagnostic(status.name, level, status.message, r.now())

    subscribe = node.create_subscription
    subscribe(VehicleEstimate, f"{namespace}/estimate", r.add(on_estimate), RELIABLE)
    subscribe(PartCalibration, f"{namespace}/calibration", r.add(on_calibration), LATCHED)
    subscribe(SpeedStatus, f"{namespace}/speed/status", r.add(on_status), RELIABLE)
    subscribe(DriveState, f"{namespace}/drive/state", r.add(on_drive), RELIABLE)
    subscribe(PartStateArray, f"{namespace}/parts/state", r.add(on_parts), RELIABLE)
    subscribe(PartExit, f"{namespace}/parts/exit", r.add(on_exit), RELIABLE)
    subscribe(DiagnosticArray, "/diagnostics", r.add(on_diagnostics), RELIABLE)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    return context, executor, thread


def calibration_values(m: PartCalibration) -> dict[str, float]:
    """The part model a calibration message states, with its uncertainties (rounded)."""
    return {
        "stick_limit_mps2": round(m.stick_limit_mps2, 4),
        "stick_limit_uncertainty": round(m.stick_limit_uncertainty, 4),
        "slip_deceleration_mps2": round(m.slip_deceleration_mps2, 4),
        "slip_deceleration_uncertainty": round(m.slip_deceleration_uncertainty, 4),
        "stick_slip_correlation": round(m.stick_slip_correlation, 3),
        "accelerometer_gain": round(m.accelerometer_gain, 4),
        "accelerometer_gain_uncertainty": round(m.accelerometer_gain_uncertainty, 4),
        "transits_used": m.transits_used,
        "operating_points": m.operating_points,
    }


def true_speed(parts: list[tuple[float, dict[int, float]]], t0: float, t1: float) -> float:
    """Mean speed of the parts on the track between sim times t0 and t1 (ground truth): for each
    part on the track from the first sample to the last, the slope of the least-squares line
    through its positions; their mean.

    A part's position swings within each drive cycle (it slips back and forth on the track: about
    1 mm peak to peak at 30 Hz), so the difference of the two end samples of a 4 s span errs by
    up to 3 % of 8 mm/s; the line through every sample averages the swing out."""
    inside = [(t, p) for t, p in parts if t0 <= t <= t1]
    if len(inside) < 2 or inside[-1][0] <= inside[0][0]:
        return math.nan
    common = sorted(set(inside[0][1]) & set(inside[-1][1]))
    x = np.array([[p.get(part, math.nan) for part in common] for _, p in inside]).reshape(
        len(inside), len(common)
    )
    x = x[:, np.all(np.isfinite(x), axis=0)]  # the parts on the track all along
    if x.shape[1] == 0:
        return math.nan
    t = np.array([t for t, _ in inside])
    t -= t.mean()
    return float(np.mean(t @ (x - x.mean(axis=0)) / (t @ t)))


def summarise(
    recording: Recording, timeline: list[dict[str, Any]], out: Path, hold_s: float = 4.0
) -> dict[str, Any]:
    """Per target-speed phase: the target, what the estimator, sensors and truth said at its end."""
    phases = []
    for entry in timeline:
        if entry["step"] != "speed status":
            continue
        # the truth over the phase's last hold_s (the part positions carry the carrier's
        # vibration: a longer span averages it out)
        truth = true_speed(recording.parts, entry["wall_s"] - hold_s, entry["wall_s"])
        phases.append(
            {
                "at_s": round(entry["wall_s"] - recording.start, 1),
                "target_mm_s": entry.get("target_mm_s"),
                "estimated_mm_s": entry.get("estimated_mm_s"),
                "estimate_uncertainty_mm_s": entry.get("estimate_uncertainty_mm_s"),
                "transit_mm_s": entry.get("transit_mm_s"),
                "true_mm_s": None if math.isnan(truth) else round(truth * 1e3, 2),
                "feed_rate_ppm": entry.get("feed_rate_ppm"),
                "monitor": f"{entry.get('level')} {entry.get('message')}",
                "calibration": next(
                    (c for t, c in reversed(recording.calibrations) if t <= entry["wall_s"]), None
                ),
            }
        )
    watchdog = next((e for e in timeline if e["step"] == "watchdog"), {})
    calibration = dict(recording.calibration)
    if "first_at" in calibration:
        calibration["first_at_s"] = round(calibration.pop("first_at") - recording.start, 1)
    summary = {
        "phases": phases,
        "calibration": calibration,
        "watchdog": watchdog,
        "feed_parts": next((e for e in timeline if e["step"] == "feed_parts"), {}),
        "parts_fed": len(recording.exits),
        "diagnostics": {
            name: LEVELS[min(level, 3)] for name, level in recording.diagnostics.items()
        },
        "diagnostic_messages": dict(recording.diagnostic_messages),
        "diagnostic_at_s": {
            name: round(t - recording.start, 1) for name, t in recording.diagnostic_times.items()
        },
        "controller_steps": timeline,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def problems(
    summary: dict[str, Any],
    controller_code: int | None,
    cell_code: int,
    expected_error: str,
    missing_nodes: Sequence[str] = (),
    tolerance: float = DEFAULT_MONITOR_TOLERANCE,
) -> list[str]:
    """Why the demo did not show a working cell (empty: it did).

    The cell works when all its nodes come up (``missing_nodes`` names those that did not; the
    controller is then not started: ``controller_code`` None), the controller and the cell exit
    cleanly, the speed monitor judges every target-speed phase OK with an estimate in it and the
    truth lies within its band (``tolerance``, relative) as that OK claims, parts
    leave the track, the watchdog trips when the controller's heartbeat stops, feed_parts (when the
    controller ran it) delivers its parts, and no node
    reports ERROR (or STALE) except ``expected_error``, the drive interface's status that the
    watchdog trip raises."""
    found = []
    if missing_nodes:
        found.append(
            f"the cell's nodes did not all come up within {STARTUP_LIMIT_S:g} s: missing "
            + ", ".join(missing_nodes)
        )
    if controller_code is None:
        found.append("the cell controller was not started")
    elif controller_code != 0:
        found.append(f"the cell controller exited with status {controller_code}")
    if cell_code != 0:
        found.append(f"the cell (feeder cell) exited with status {cell_code}")
    if not summary["phases"]:
        found.append("no target-speed phase was recorded (the controller never watched a speed)")
    for phase in summary["phases"]:
        where = f"phase ending at {phase['at_s']:g} s (target {phase['target_mm_s']} mm/s)"
        if phase["estimated_mm_s"] is None:
            found.append(f"{where}: no speed estimate")
        if not str(phase["monitor"]).startswith("OK "):
            found.append(f"{where}: the speed monitor said {phase['monitor']}")
        true, target = phase["true_mm_s"], phase["target_mm_s"]
        if true is None or target is None:
            found.append(f"{where}: no ground truth recorded")
        elif abs(true - target) > tolerance * abs(target):
            off = 100 * (true / target - 1)
            found.append(
                f"{where}: the part ran at {true:g} mm/s in truth, {off:+.1f} % off the target, "
                f"outside the {100 * tolerance:g} % the speed monitor confirmed"
            )
    if summary["calibration"].get("transits_used", 0) == 0:
        found.append("the part model was not calibrated from the sensor transits")
    if summary["parts_fed"] == 0:
        found.append("no part left the track")
    if summary["watchdog"].get("tripped") is not True:
        found.append("the watchdog did not trip when the controller's heartbeat stopped")
    feed = summary.get("feed_parts", {})
    if feed and feed.get("outcome") != "succeeded":
        found.append(
            f"feed_parts ended {feed.get('outcome')}: {feed.get('reason')} "
            f"({feed.get('delivered')} parts delivered)"
        )
    messages, times = summary["diagnostic_messages"], summary["diagnostic_at_s"]
    for name, level in sorted(summary["diagnostics"].items()):
        if level in ("ERROR", "STALE") and name != expected_error:
            found.append(f"{level} from {name} at {times[name]:g} s: {messages[name]}")
    return found


def monitor_tolerance(cell_file: Path, namespace: str) -> float:
    """The speed monitor's ``speed_tolerance`` for the feeder in ``namespace`` of the cell."""
    for launch in load_cell(cell_file).nodes:
        if launch.executable == "speed_monitor" and launch.namespace == namespace:
            return float(launch.parameters.get("speed_tolerance", DEFAULT_MONITOR_TOLERANCE))
    return DEFAULT_MONITOR_TOLERANCE


def plot(recording: Recording, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    t0 = recording.start
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(10, 7))
    if recording.status:
        s = np.array(recording.status)
        top.plot(s[:, 0] - t0, s[:, 1] * 1e3, "k--", label="target")
        top.plot(s[:, 0] - t0, s[:, 2] * 1e3, label="estimator (sensorless)")
        top.plot(s[:, 0] - t0, s[:, 3] * 1e3, ".", label="sensor transit (8.5 cm)")
    if recording.estimate:
        e = np.array(recording.estimate)
        top.fill_between(
            e[:, 0] - t0, (e[:, 1] - 2 * e[:, 2]) * 1e3, (e[:, 1] + 2 * e[:, 2]) * 1e3,
            alpha=0.25, label="estimate +- 2 sigma (95 %)",
        )  # fmt: skip
    if len(recording.parts) > 20:
        t = np.array([row[0] for row in recording.parts])
        truth = np.array(
            [(t[k] - t0, true_speed(recording.parts, t[k] - 2.0, t[k])) for k in range(20, t.size)]
        )
        top.plot(truth[:, 0], truth[:, 1] * 1e3, alpha=0.6, label="truth (simulator)")
    top.set_ylabel("part speed [mm/s]")
    top.legend(loc="upper right")
    top.grid(True)
    if recording.drive:
        d = np.array(recording.drive)
        d[:, 0] -= t0
        bottom.plot(d[:, 0], d[:, 2], label="frequency [Hz]")
        bottom.plot(d[:, 0], d[:, 3], label="amplitude [%]")
        faults = d[:, 1] >= 3
        if faults.any():
            bottom.fill_between(
                d[:, 0], 0, 1, where=faults, transform=bottom.get_xaxis_transform(),
                color="red", alpha=0.2, label="fault / e-stop",
            )  # fmt: skip
    bottom.set_xlabel("time [s]")
    bottom.legend(loc="upper right")
    bottom.grid(True)
    fig.tight_layout()
    path = out / "cell_speed_and_drive.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--output", type=Path, default=Path("demo-output"))
    parser.add_argument("--cell", type=Path, default=REPO / "config" / "cell.yaml")
    parser.add_argument("--namespace", default="/demo_cell/feeder_1")
    parser.add_argument(
        "--hold", type=float, default=6.0, help="seconds at each target speed once confirmed"
    )
    parser.add_argument(
        "--timeout", type=float, default=75.0, help="at most this long to confirm each target"
    )
    parser.add_argument(
        "--composed", action="store_true", help="run the cell's nodes in one process"
    )
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    bin_dir = Path(sys.executable).parent
    started = time.monotonic()

    recording = Recording()
    context, executor, thread = _probe(args.namespace, recording)
    expected = [launch.fully_qualified_name for launch in load_cell(args.cell).nodes]
    cell = subprocess.Popen(
        [str(bin_dir / "feeder"), "cell", "--config", str(args.cell)]
        + (["--composed"] if args.composed else [])
    )
    timeline_file = args.output / "controller_timeline.json"
    timeline_file.unlink(missing_ok=True)  # an earlier run's must not pass for this one's
    controller_code: int | None = None  # None: not started (the cell did not come up)
    recorder: subprocess.Popen[bytes] | None = None
    missing: list[str] = []
    try:
        print(
            f"[demo] waiting for the cell's {len(expected)} nodes (at most {STARTUP_LIMIT_S:g} s)",
            flush=True,
        )
        missing = wait_for_nodes(
            executor.get_nodes()[0], expected, STARTUP_LIMIT_S, lambda: cell.poll() is None
        )
        if not missing:
            print(f"[demo] the cell is up after {time.monotonic() - started:.1f} s", flush=True)
            recorder = demo_recording.start(bin_dir, args.namespace, args.output)
            controller_code = subprocess.run(
                [
                    sys.executable, "-m", "feeder_ros.examples.cell_controller",
                    "--namespace", args.namespace, "--hold", str(args.hold),
                    "--timeout", str(args.timeout), "--timeline", str(timeline_file),
                ],
                timeout=600,
            ).returncode  # fmt: skip
    finally:
        with recording.lock:
            recording.collecting_diagnostics = False
        # SIGTERM, which `feeder cell` takes like Ctrl-C: a demo run as a background job of a
        # non-interactive shell starts the cell with SIGINT ignored
        cell.send_signal(signal.SIGTERM)
        cell_code = cell.wait(timeout=30)
        executor.shutdown()
        thread.join(timeout=5)
        rclpy.shutdown(context=context)
        report = "report: none (the cell did not come up)"
        if recorder is not None:
            report = demo_recording.finish(recorder, args.namespace, args.output)

    timeline = json.loads(timeline_file.read_text()) if timeline_file.exists() else []
    summary = summarise(recording, timeline, args.output, args.hold)
    plots = plot(recording, args.output)
    print()
    print("== feeder cell demo: summary ==")
    print(f"{'phase end':>9} {'target':>8} {'estimate':>9} {'sensors':>8} {'truth':>8} {'feed':>6}")
    print(
        f"{'[s]':>9} {'[mm/s]':>8} {'[mm/s]':>9} {'[mm/s]':>8} {'[mm/s]':>8} {'[ppm]':>6}  monitor"
    )
    for phase in summary["phases"]:
        values = [
            phase[k]
            for k in ("target_mm_s", "estimated_mm_s", "transit_mm_s", "true_mm_s", "feed_rate_ppm")
        ]
        text = [f"{v:8.2f}" if isinstance(v, int | float) else f"{'-':>8}" for v in values]
        print(f"{phase['at_s']:9.1f} {text[0]} {text[1]:>9} {text[2]} {text[3]} {text[4]:>6}  "
              f"{phase['monitor']}")  # fmt: skip
    watchdog = summary["watchdog"]
    print(
        f"watchdog: tripped={watchdog.get('tripped')} "
        f"state={watchdog.get('state')} reason={watchdog.get('reason')!r}"
    )
    feed = summary["feed_parts"]
    print(
        f"feed_parts: {feed.get('outcome', 'not run')}, {feed.get('delivered', 0)} parts in "
        f"{feed.get('elapsed_s', '-')} s ({feed.get('reason', '')}); "
        f"drive {feed.get('state_after')}"
    )
    print(f"parts fed: {summary['parts_fed']}")
    cal = summary["calibration"]
    print(
        f"part model: {cal.get('state', 'not heard')} after {cal.get('transits_used', 0)} "
        f"transits at {cal.get('operating_points', 0)} operating point(s) (first at "
        f"{cal.get('first_at_s', '-')} s): mu_s {cal.get('static_friction', '-')}, mu_d "
        f"{cal.get('kinetic_friction', '-')}, accelerometer gain "
        f"{cal.get('accelerometer_gain', '-')} (the simulated plant: 0.245, 0.088, 1.02)"
    )
    print("diagnostics seen until the cell stopped (worst level per status):")
    for name, level in sorted(summary["diagnostics"].items()):
        message, at = summary["diagnostic_messages"][name], summary["diagnostic_at_s"][name]
        detail = f" ({message}; first at {at:g} s)" if level != "OK" else ""
        print(f"  {level:5} {name}{detail}")
    print(f"plots: {', '.join(str(p) for p in plots)}; data: {args.output / 'summary.json'}")
    print(report)
    print(f"demo took {time.monotonic() - started:.0f} s")
    tolerance = monitor_tolerance(args.cell, args.namespace)
    landed = [
        abs(p["true_mm_s"] / p["target_mm_s"] - 1.0) <= LANDING_GOAL
        for p in summary["phases"]
        if p["true_mm_s"] is not None and p["target_mm_s"]
    ]
    print(
        f"landing: {sum(landed)} of {len(landed)} phases within {100 * LANDING_GOAL:g} % of the "
        f"target in truth (the estimator's goal after calibration); the verdict checks the "
        f"monitor's {100 * tolerance:g} % band"
    )
    found = problems(
        summary,
        controller_code,
        cell_code,
        f"{args.namespace}/drive_interface: drive",
        missing,
        tolerance,
    )
    if found:
        print("DEMO FAILED: the cell did not work as the demo expects:")
        for problem in found:
            print(f"  - {problem}")
        return 1
    print("DEMO OK")
    return 0


if __name__ == "__main__":
    sys.exit(main())
