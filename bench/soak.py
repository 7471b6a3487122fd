"""Soak: the demo cell for a long wall time, with a controller changing the target speed every
minute. Measured per node: CPU and resident memory after a warm-up and at the end, both at the first
speed (growth); on
the wire: IMU and carrier-state samples missing from their grids; diagnostics ERRORs.

    python bench/soak.py --minutes 30          # the issue's soak (not part of make bench)
    python bench/soak.py --minutes 3 --json out.json

Targets (issue 33): RSS and CPU growth < 5 % from start to end, 0 missing samples, 0 ERRORs.
``cpu_per_minute`` gives each node's CPU over every minute of the run (with the speed of that
minute), to tell a trend from the bursts of the estimator's calibration work.
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
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy

from feeder_ros.examples.cell_controller import CellController
from feeder_ros.msg import AccelerometerBatch, CarrierStateBatch
from feeder_ros.ros_compat import RosSession

NAMESPACE = "/demo_cell/feeder_1"
SPEEDS_MPS = (0.015, 0.008, 0.012, 0.010)
NODES = ("platform_simulator", "vehicle_estimator", "drive_interface", "speed_monitor")
TICK_S = os.sysconf("SC_CLK_TCK")


class Grid:
    """Samples on a fixed grid: counts the ones that should have come and did not."""

    def __init__(self) -> None:
        self.received = 0
        self.missing = 0
        self._next_ns: int | None = None

    def batch(self, stamp_ns: int, period_s: float, count: int) -> None:
        period_ns = round(period_s * 1e9)
        if self._next_ns is not None and period_ns > 0:
            gap = round((stamp_ns - self._next_ns) / period_ns)
            self.missing += max(gap, 0)
        self._next_ns = stamp_ns + count * period_ns
        self.received += count


def _usage(pid: int) -> tuple[float, int]:
    """CPU seconds so far and resident memory [bytes] of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    cpu_s = (int(fields[11]) + int(fields[12])) / TICK_S
    rss_pages = int(Path(f"/proc/{pid}/statm").read_text().split()[1])
    return cpu_s, rss_pages * os.sysconf("SC_PAGE_SIZE")


def _node_pids(cell_pid: int) -> dict[str, int]:
    found: dict[str, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            line = (entry / "cmdline").read_bytes().decode()
        except (OSError, ValueError, IndexError):
            continue
        for node in NODES:
            if parent == cell_pid and f"/{node}\0" in line:
                found[node] = int(entry.name)
    return found


def _window(pids: dict[str, int], seconds: float) -> dict[str, dict[str, float]]:
    """CPU share (% of one core) over ``seconds`` and RSS at its end, per node."""
    before = {node: _usage(pid) for node, pid in pids.items()}
    time.sleep(seconds)
    after = {node: _usage(pid) for node, pid in pids.items()}
    return {
        node: {
            "cpu_percent": 100.0 * (after[node][0] - before[node][0]) / seconds,
            "rss_mib": after[node][1] / 2**20,
        }
        for node in pids
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--minutes", type=float, default=30.0, help="wall time of the soak")
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    cell = subprocess.Popen([str(Path(sys.executable).parent / "feeder"), "cell"])
    imu, state = Grid(), Grid()
    errors: dict[str, int] = {}
    try:
        with RosSession():
            controller = CellController(NAMESPACE)
            best_effort = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
            reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)

            def on_imu(m: AccelerometerBatch) -> None:
                stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
                imu.batch(stamp, m.sample_period_s, len(m.acceleration_x_mps2))

            def on_state(m: CarrierStateBatch) -> None:
                stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
                state.batch(stamp, m.sample_period_s, len(m.displacement_m))

            def on_diagnostics(m: Any) -> None:
                for status in m.status:
                    if int.from_bytes(status.level, "little") >= 2:
                        key = f"{status.name}: {status.message}"
                        errors[key] = errors.get(key, 0) + 1

            controller.create_subscription(AccelerometerBatch, "imu/batch", on_imu, best_effort)
            controller.create_subscription(
                CarrierStateBatch, "carrier/state_batch", on_state, reliable
            )
            controller.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 100)
            executor = SingleThreadedExecutor()
            executor.add_node(controller)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()
            results = _soak(controller, cell.pid, args.minutes, imu, state, errors)
            executor.shutdown()
            spinner.join(timeout=5)
    finally:
        cell.send_signal(signal.SIGTERM)
        cell.wait(timeout=30)
    print(json.dumps(results, indent=2))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


def _soak(
    controller: CellController,
    cell_pid: int,
    minutes: float,
    imu: Grid,
    state: Grid,
    errors: dict[str, int],
) -> dict[str, Any]:
    controller.wait_for(
        "the drive interface", lambda: _node_pids(cell_pid).keys() >= set(NODES), 180
    )
    pids = _node_pids(cell_pid)
    controller.bring_up()
    controller.target_speed(SPEEDS_MPS[0])
    controller.start(wait_s=30.0)
    time.sleep(60.0)  # warm-up: start-up, first calibration
    warm_up_errors = dict(errors)
    errors.clear()
    imu.missing = state.missing = 0
    start = _window(pids, 30.0)
    began = time.monotonic()
    change = 1
    series: list[dict[str, Any]] = []  # CPU per node over each speed's minute
    while time.monotonic() - began < minutes * 60.0 - 30.0:
        span = min(60.0, max(minutes * 60.0 - 30.0 - (time.monotonic() - began), 0.0))
        if span > 1.0:
            minute = _window(pids, span)
            series.append(
                {
                    "minute": round((time.monotonic() - began) / 60.0, 2),
                    "speed_mm_s": 1e3 * SPEEDS_MPS[(change - 1) % len(SPEEDS_MPS)],
                    **{node: round(v["cpu_percent"], 1) for node, v in minute.items()},
                }
            )
        controller.target_speed(SPEEDS_MPS[change % len(SPEEDS_MPS)])
        change += 1
    # the end window at the start window's speed (the work per second depends on the setting)
    controller.target_speed(SPEEDS_MPS[0])
    time.sleep(45.0)
    end = _window(pids, 30.0)
    growth = {
        node: {
            "rss_growth_percent": 100.0 * (end[node]["rss_mib"] / start[node]["rss_mib"] - 1.0),
            "cpu_growth_percent": (
                100.0 * (end[node]["cpu_percent"] / start[node]["cpu_percent"] - 1.0)
                if start[node]["cpu_percent"] > 0.0
                else math.nan
            ),
        }
        for node in pids
    }
    return {
        "minutes": minutes,
        "speed_changes": change - 1,
        "start": start,
        "end": end,
        "growth": growth,
        "cpu_per_minute": series,
        "imu_samples": imu.received,
        "imu_missing": imu.missing,
        "state_samples": state.received,
        "state_missing": state.missing,
        "diagnostics_errors": errors,
        "diagnostics_errors_in_warm_up": warm_up_errors,
    }


if __name__ == "__main__":
    sys.exit(main())
