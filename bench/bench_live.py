#!/usr/bin/env python3
"""Live performance of the nodes as separate processes over real DDS (a benchmark, not a test).

1. Paced: ``platform_simulator`` at 1 kHz IMU + 1 kHz carrier state in real time for ``--seconds``
   (60 by default); a probe process takes every message raw (no deserialisation; the stamps are
   read from the CDR bytes) and counts samples missing or duplicated on each stream. The baseline
   is the wall clock: the achieved real-time factor should be 1.
2. Unpaced: the simulator with ``use_sim_time`` and ``real_time_factor:=0`` (as fast as the
   machine allows), per-sample messages and batches; reports simulated seconds per wall second
   from ``/clock``.
3. Estimator headroom: the estimator fed a paced 1 kHz stream (per-sample ``Imu`` messages, then
   batches); its CPU seconds per second of data (headroom = 1 / that).

Run: ``python bench/bench_live.py [--seconds 60] [--quick] [--output FILE.md]``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import shutil
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import Imu

from feeder_ros.msg import CarrierState

BIN = Path(sys.executable).parent
RELIABLE = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
BEST_EFFORT = QoSProfile(depth=5000, reliability=ReliabilityPolicy.BEST_EFFORT)


def _stamp_ns(cdr: bytes) -> int:
    """header.stamp of a serialised message whose first field is a std_msgs/Header."""
    sec, nanosec = struct.unpack_from("<iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


class StampCounter:
    """Counts samples on a fixed grid from message stamps: received, missing, duplicated."""

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns
        self.stamps: list[int] = []
        self.lock = threading.Lock()

    def add(self, stamp_ns: int) -> None:
        with self.lock:
            self.stamps.append(stamp_ns)

    def summary(self) -> tuple[int, int, int]:
        with self.lock:
            stamps = sorted(self.stamps)
        if len(stamps) < 2:
            return len(stamps), 0, 0
        steps = [b - a for a, b in itertools.pairwise(stamps)]
        duplicated = sum(1 for step in steps if step == 0)
        missing = sum(max(round(step / self.period_ns) - 1, 0) for step in steps)
        return len(stamps), missing, duplicated


def _start(command: Sequence[str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen(list(command), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _stop(process: subprocess.Popen[bytes]) -> float:
    """Ctrl-C the process; returns its CPU seconds (user + system)."""
    process.send_signal(2)
    process.wait(timeout=20)
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def paced(seconds: float) -> list[str]:
    ns = "/bench_live_paced"
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("bench_probe", context=context)
    imu = StampCounter(1_000_000)
    state = StampCounter(1_000_000)
    node.create_subscription(
        Imu, f"{ns}/imu", lambda m: imu.add(_stamp_ns(m)), BEST_EFFORT, raw=True
    )
    node.create_subscription(
        CarrierState, f"{ns}/carrier/state", lambda m: state.add(_stamp_ns(m)), RELIABLE, raw=True
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    process = _start(
        [
            str(BIN / "platform_simulator"), "--ros-args", "-r", f"__ns:={ns}",
            "-p", "imu_rate_hz:=1000.0", "-p", "state_rate_hz:=1000.0",
            "-p", "damping_ns_per_m:=200.0", "-p", "drive_amplitude_n:=40.0",
        ]
    )  # fmt: skip
    deadline = time.monotonic() + 60.0
    while not state.stamps and time.monotonic() < deadline:
        time.sleep(0.05)
    first_wall = time.monotonic()
    time.sleep(seconds)
    with state.lock:
        sim_span = (state.stamps[-1] - state.stamps[0]) * 1e-9 if state.stamps else 0.0
    wall_span = time.monotonic() - first_wall
    cpu_after = _stop(process)
    executor.shutdown()
    spinner.join(timeout=5)
    node.destroy_node()
    rclpy.shutdown(context=context)
    cpu = cpu_after - (cpu_before.ru_utime + cpu_before.ru_stime)
    rows = []
    for name, counter, qos in (("imu", imu, "best effort"), ("carrier/state", state, "reliable")):
        received, missing, duplicated = counter.summary()
        rows.append(
            f"| {name} ({qos}) | 1000 Hz | {received} | {missing} | {duplicated} | "
            f"{sim_span / wall_span:.3f} | {cpu / max(sim_span, 1e-9):.3f} |"
        )
    return [
        f"Paced, {seconds:.0f} s: `platform_simulator` (1 kHz IMU + 1 kHz state) -> raw probe",
        "",
        "| stream | rate | received | missing | duplicated | sim s per wall s | "
        "simulator CPU s per sim s |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]


def unpaced(seconds: float, batches: bool) -> str:
    ns = f"/bench_live_fast_{int(batches)}"
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("bench_clock_probe", context=context)
    clocks: list[int] = []
    node.create_subscription(
        ClockMessage, "/clock", lambda m: clocks.append(_clock_ns(m)), 100, raw=True
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    process = _start(
        [
            str(BIN / "platform_simulator"), "--ros-args", "-r", f"__ns:={ns}",
            "-p", "use_sim_time:=true", "-p", "real_time_factor:=0.0", "-p", "max_step_s:=0.2",
            "-p", "imu_rate_hz:=1000.0", "-p", "state_rate_hz:=1000.0",
            "-p", f"publish_batches:={'true' if batches else 'false'}",
            "-p", "damping_ns_per_m:=200.0", "-p", "drive_amplitude_n:=40.0",
        ]
    )  # fmt: skip
    deadline = time.monotonic() + 60.0
    while len(clocks) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    start_wall, start_sim = time.monotonic(), clocks[-1]
    time.sleep(seconds)
    factor = (clocks[-1] - start_sim) * 1e-9 / (time.monotonic() - start_wall)
    _stop(process)
    executor.shutdown()
    spinner.join(timeout=5)
    node.destroy_node()
    rclpy.shutdown(context=context)
    kind = "batches (`imu/batch`, `carrier/state_batch`)" if batches else "one message per sample"
    return f"| {kind} | 1000 Hz + 1000 Hz | {factor:.1f}x |"


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a running process, from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def estimator_headroom(seconds: float) -> list[str]:
    """The estimator on a paced 1 kHz stream: its CPU seconds per second of data."""
    rows = []
    for batches in (False, True):
        ns = f"/bench_live_estimator_{int(batches)}"
        simulator = _start(
            [
                str(BIN / "platform_simulator"), "--ros-args", "-r", f"__ns:={ns}",
                "-p", "imu_rate_hz:=1000.0", "-p", "state_rate_hz:=10.0",
                "-p", f"publish_batches:={'true' if batches else 'false'}",
                "-p", "damping_ns_per_m:=200.0",
            ]
        )  # fmt: skip
        drive = _start(
            [
                str(BIN / "manual_drive"), "--ros-args", "-r", f"__ns:={ns}",
                "-p", "frequency_hz:=20.0", "-p", "amplitude_n:=40.0",
            ]
        )  # fmt: skip
        estimator = _start([str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}"])
        time.sleep(8.0)  # start-up (imports, solver cache) and the first fits
        cpu0, wall0 = _cpu_seconds(estimator.pid), time.monotonic()
        time.sleep(seconds)
        cpu = _cpu_seconds(estimator.pid) - cpu0
        wall = time.monotonic() - wall0
        for process in (estimator, drive, simulator):
            _stop(process)
        load = cpu / wall
        kind = "AccelerometerBatch (imu/batch)" if batches else "sensor_msgs/Imu, one per sample"
        rows.append(f"| {kind} | 1000 Hz | {load:.3f} | {1.0 / load:.1f}x |")
    return [
        f"Estimator on a paced 1 kHz accelerometer stream, {seconds:.0f} s: CPU of the "
        "`vehicle_estimator` process per second of data (headroom = 1 / load; target >= 5x)",
        "",
        "| input | rate | CPU s per s | headroom |",
        "|---|---|---|---|",
        *rows,
        "",
    ]


def _clock_ns(cdr: bytes) -> int:
    sec, nanosec = struct.unpack_from("<iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--quick", action="store_true", help="5 s runs")
    parser.add_argument("--output", type=Path)
    args = parser.parse_args()
    if shutil.which("platform_simulator", path=str(BIN)) is None:
        print("platform_simulator is not installed in this venv: run `make install`")
        return 2
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    seconds = 5.0 if args.quick else args.seconds
    lines = ["### Live nodes over DDS", ""]
    lines += paced(seconds)
    lines += [
        "Unpaced (`use_sim_time`, `real_time_factor:=0`), "
        f"{min(seconds, 10.0):.0f} s: simulated seconds per wall second from `/clock`",
        "",
        "| publishing | streams | real-time factor |",
        "|---|---|---|",
        unpaced(min(seconds, 10.0), batches=False),
        unpaced(min(seconds, 10.0), batches=True),
        "",
    ]
    if (BIN / "vehicle_estimator").exists():
        lines += estimator_headroom(min(seconds, 20.0))
    report = "\n".join(lines)
    print(report)
    if args.output:
        args.output.write_text(report + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
