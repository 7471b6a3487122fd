"""`make demo`'s verdict: DEMO OK only for a cell that did what the demo shows."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from ros_test_tools import probe_node

from feeder_ros.demo import (
    DEFAULT_MONITOR_TOLERANCE,
    STARTUP_LIMIT_S,
    Recording,
    monitor_tolerance,
    problems,
    summarise,
    true_speed,
    wait_for_nodes,
)

NS = "/demo_cell/feeder_1"
DRIVE = f"{NS}/drive_interface: drive"
ESTIMATE = f"{NS}/vehicle_estimator: estimate"
MONITOR = f"{NS}/speed_monitor: part speed"


def _status(wall_s: float, target: float, estimate: float | None, level: str, message: str) -> Any:
    return {
        "t_s": wall_s,
        "wall_s": wall_s,
        "step": "speed status",
        "target_mm_s": target,
        "estimated_mm_s": estimate,
        "transit_mm_s": estimate,
        "feed_rate_ppm": 15.0,
        "level": level,
        "message": message,
    }


def _run(
    tmp_path: Path,
    estimates: tuple[float | None, float | None] = (15.3, 8.2),
    monitor: tuple[tuple[str, str], ...] = (("OK", "at target"), ("OK", "at target")),
    tripped: bool = True,
    exits: int = 3,
    diagnostics: tuple[tuple[str, int, str], ...] = (),
    truths: tuple[float, float] = (15.2, 7.9),
    transits: int = 6,
) -> dict[str, Any]:
    recording = Recording(start=1000.0)
    recording.exits = [1010.0 + k for k in range(exits)]
    # the simulator's part positions: each phase's last 4 s at its true speed [mm/s]
    for part, (end, speed) in enumerate(zip((1019.6, 1031.6), truths, strict=True)):
        recording.parts += [(end - 4.0, {part: 0.0}), (end, {part: 4.0 * speed * 1e-3})]
    if transits:
        recording.calibration.update(first_at=1012.0, state="calibrating", transits_used=transits)
    seen: list[str] = []  # statuses noted so far: the k-th at 5 + k s
    for name, level, message in (
        (DRIVE, 0, "running"),
        (DRIVE, 2, "fault: heartbeat lost: none for 2.01 s (timeout 2 s)"),
        (DRIVE, 2, "fault: still latched"),
        (DRIVE, 0, "running"),
        (ESTIMATE, 1, "waiting for the first accelerometer sample (0.9 s since start)"),
        (ESTIMATE, 0, "estimating"),
        *diagnostics,
    ):
        recording.note_diagnostic(name, level, message, recording.start + 5.0 + len(seen))
        seen.append(name)
    timeline = [
        _status(1019.6, 15.0, estimates[0], *monitor[0]),
        _status(1031.6, 8.0, estimates[1], *monitor[1]),
        {"step": "watchdog", "wall_s": 1033.0, "tripped": tripped, "state": "fault"},
    ]
    return summarise(recording, timeline, tmp_path)


def test_a_working_cell_passes_and_its_summary_keeps_the_worst_messages(tmp_path: Path) -> None:
    summary = _run(tmp_path)
    assert problems(summary, 0, 0, DRIVE) == []
    written = json.loads((tmp_path / "summary.json").read_text())
    assert written["diagnostics"] == {DRIVE: "ERROR", ESTIMATE: "WARN"}
    # the message that came with the worst level first, not a later one at that level
    assert written["diagnostic_messages"] == {
        DRIVE: "fault: heartbeat lost: none for 2.01 s (timeout 2 s)",
        ESTIMATE: "waiting for the first accelerometer sample (0.9 s since start)",
    }
    assert written["diagnostic_at_s"] == {DRIVE: 6.0, ESTIMATE: 9.0}  # since the demo's start
    assert [phase["true_mm_s"] for phase in written["phases"]] == [15.2, 7.9]
    assert written["calibration"] == {
        "state": "calibrating",
        "transits_used": 6,
        "first_at_s": 12.0,
    }


def test_a_speed_off_target_in_truth_or_no_calibration_fails(tmp_path: Path) -> None:
    """The monitor's OK claims the truth lies within its band: a truth outside it fails the
    demo (the band as the cell sets it); so does a part model never calibrated from transits."""
    off = _run(tmp_path, truths=(15.2, 8.3))  # 8 mm/s asked, 3.75 % fast in truth
    assert problems(off, 0, 0, DRIVE) == []  # within the default 5 % band
    assert problems(off, 0, 0, DRIVE, tolerance=0.03) == [
        "phase ending at 31.6 s (target 8.0 mm/s): the part ran at 8.3 mm/s in truth, +3.8 % off "
        "the target, outside the 3 % the speed monitor confirmed"
    ]
    far = _run(tmp_path, truths=(15.2, 8.5))  # 6.25 % fast
    assert problems(far, 0, 0, DRIVE) == [
        "phase ending at 31.6 s (target 8.0 mm/s): the part ran at 8.5 mm/s in truth, +6.2 % off "
        "the target, outside the 5 % the speed monitor confirmed"
    ]
    assert problems(_run(tmp_path, transits=0), 0, 0, DRIVE) == [
        "the part model was not calibrated from the sensor transits"
    ]


def test_the_band_is_the_cells_speed_monitor_tolerance() -> None:
    cell = Path(__file__).resolve().parents[1] / "config" / "cell.yaml"
    assert monitor_tolerance(cell, NS) == 0.05
    assert monitor_tolerance(cell, "/elsewhere") == DEFAULT_MONITOR_TOLERANCE


def test_a_cell_whose_simulator_never_came_up_fails_with_every_reason(tmp_path: Path) -> None:
    # what a run looked like whose simulator was still compiling its solver: the controller
    # drove, nothing moved, the estimator and monitor raised errors; the old verdict said OK
    summary = _run(
        tmp_path,
        estimates=(None, None),
        monitor=(("ERROR", "sensor timeout"), ("ERROR", "starvation, sensor timeout")),
        exits=0,
        diagnostics=(
            (ESTIMATE, 2, "no accelerometer sample in 10.2 s since start"),
            (MONITOR, 2, "sensor timeout"),
            (MONITOR, 2, "starvation, sensor timeout"),
        ),
    )
    assert problems(summary, 0, 0, DRIVE) == [
        "phase ending at 19.6 s (target 15.0 mm/s): no speed estimate",
        "phase ending at 19.6 s (target 15.0 mm/s): the speed monitor said ERROR sensor timeout",
        "phase ending at 31.6 s (target 8.0 mm/s): no speed estimate",
        "phase ending at 31.6 s (target 8.0 mm/s): the speed monitor said ERROR starvation, "
        "sensor timeout",
        "no part left the track",
        f"ERROR from {MONITOR} at 12 s: sensor timeout",
        f"ERROR from {ESTIMATE} at 11 s: no accelerometer sample in 10.2 s since start",
    ]


def test_each_missing_piece_is_named_alone(tmp_path: Path) -> None:
    assert problems(_run(tmp_path, tripped=False), 0, 0, DRIVE) == [
        "the watchdog did not trip when the controller's heartbeat stopped"
    ]
    slow = _run(tmp_path, monitor=(("OK", "at target"), ("WARN", "below target: 6.1 mm/s")))
    assert problems(slow, 0, 0, DRIVE) == [
        "phase ending at 31.6 s (target 8.0 mm/s): the speed monitor said WARN below target: "
        "6.1 mm/s"
    ]
    assert problems(_run(tmp_path), 1, -2, DRIVE) == [
        "the cell controller exited with status 1",
        "the cell (feeder cell) exited with status -2",
    ]
    stale = _run(tmp_path, diagnostics=((f"{NS}/platform_simulator: simulation", 3, "stale"),))
    assert problems(stale, 0, 0, DRIVE) == [
        f"STALE from {NS}/platform_simulator: simulation at 11 s: stale"
    ]
    # the drive interface's ERROR is the demo's own watchdog trip only under its expected name
    assert problems(_run(tmp_path), 0, 0, "/other/drive_interface: drive") == [
        f"ERROR from {DRIVE} at 6 s: fault: heartbeat lost: none for 2.01 s (timeout 2 s)"
    ]
    assert problems(summarise(Recording(), [], tmp_path), 0, 0, DRIVE) == [
        "no target-speed phase was recorded (the controller never watched a speed)",
        "the part model was not calibrated from the sensor transits",
        "no part left the track",
        "the watchdog did not trip when the controller's heartbeat stopped",
    ]


def test_diagnostics_after_the_cell_is_told_to_stop_are_not_kept() -> None:
    recording = Recording()
    recording.note_diagnostic(ESTIMATE, 0, "estimating", 1.0)
    recording.collecting_diagnostics = False
    recording.note_diagnostic(ESTIMATE, 2, "sensor timeout: no accelerometer sample for 1.2 s", 2.0)
    assert recording.diagnostics == {ESTIMATE: 0}
    assert recording.diagnostic_messages == {ESTIMATE: "estimating"}


def test_a_cell_whose_nodes_did_not_come_up_is_named_and_its_controller_not_counted(
    tmp_path: Path,
) -> None:
    missing = [f"{NS}/drive_interface", f"{NS}/speed_monitor"]
    found = problems(_run(tmp_path), None, 0, DRIVE, missing)
    assert found == [
        f"the cell's nodes did not all come up within {STARTUP_LIMIT_S:g} s: missing "
        f"{NS}/drive_interface, {NS}/speed_monitor",
        "the cell controller was not started",
    ]


def test_waiting_for_nodes_returns_once_they_are_in_the_graph_and_names_the_missing() -> None:
    with probe_node("demo_wait_probe") as probe:
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node("cell_node", namespace="/demo_wait/feeder_9", context=context)
        try:
            started = time.monotonic()
            assert (
                wait_for_nodes(probe, ["/demo_wait/feeder_9/cell_node"], 30.0, lambda: True) == []
            )
            assert time.monotonic() - started < 30.0
            # a node that never comes: named after the limit
            started = time.monotonic()
            absent = ["/demo_wait/feeder_9/cell_node", "/demo_wait/feeder_9/never"]
            assert wait_for_nodes(probe, absent, 0.5, lambda: True) == ["/demo_wait/feeder_9/never"]
            assert 0.5 <= time.monotonic() - started < 10.0
            # a cell process that has exited: no waiting for the limit
            started = time.monotonic()
            assert wait_for_nodes(probe, absent, 60.0, lambda: False) == [
                "/demo_wait/feeder_9/never"
            ]
            assert time.monotonic() - started < 10.0
        finally:
            node.destroy_node()
            rclpy.shutdown(context=context)


def test_a_feed_parts_goal_that_did_not_deliver_fails_the_demo(tmp_path: Path) -> None:
    summary = _run(tmp_path)
    summary["feed_parts"] = {
        "step": "feed_parts",
        "outcome": "succeeded",
        "delivered": 3,
        "reason": "delivered 3 parts in 4.1 s",
    }
    assert problems(summary, 0, 0, DRIVE) == []
    summary["feed_parts"] = {
        "step": "feed_parts",
        "outcome": "starved",
        "delivered": 1,
        "reason": "starved: no part past sensor 1 for 20.0 s",
    }
    assert problems(summary, 0, 0, DRIVE) == [
        "feed_parts ended starved: starved: no part past sensor 1 for 20.0 s (1 parts delivered)"
    ]


def test_the_truth_is_the_parts_mean_speed_through_their_in_cycle_swing() -> None:
    """Parts at 8 mm/s that swing +-0.5 mm at 30 Hz, sampled at 50 Hz (the demo's parts/state):
    the end samples of a 4 s span can be 1 mm apart beyond the travel (3 %); the truth is not
    moved by where in the swing they fall. A part put down or gone within the span is left out."""
    t = np.arange(0.0, 10.0, 0.02)
    for phase in np.linspace(0.0, 2.0 * math.pi, 7):
        swing = 0.5e-3 * np.sin(2.0 * math.pi * 30.0 * t + phase)
        parts = [
            (
                float(tk),
                {0: 0.008 * tk + sk, 1: 0.05 + 0.008 * tk + sk} | ({2: 0.0} if tk > 8 else {}),
            )
            for tk, sk in zip(t, swing, strict=True)
        ]
        # (the end samples, 5.0 and 8.96 s, fall 0.8 cycles apart: their difference errs 0.2-1.7 %)
        assert true_speed(parts, 5.0, 8.97) == pytest.approx(0.008, rel=0.001), phase
    assert math.isnan(true_speed(parts, 20.0, 24.0))  # nothing recorded then
