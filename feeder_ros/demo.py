"""``make demo``: bring up feeder nodes as separate processes and show them talking over DDS.

This is the graph smoke of the package foundation: it starts the node executables in a
namespace, watches their topics from a probe node and prints what it received. Later stages
of the suite replace it with the full simulated cell (simulator, estimator, drive interface and
speed monitor under an example cell controller).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy

from feeder_ros.msg import DriveCommand


def _executable(name: str) -> str:
    path = Path(sys.executable).parent / name
    found = str(path) if path.exists() else shutil.which(name)
    if found is None:
        raise SystemExit(f"executable {name!r} not found: run `make install` first")
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--output", type=Path, default=Path("demo-output"))
    parser.add_argument("--namespace", default="/demo_cell/feeder_1")
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    command = [
        _executable("manual_drive"),
        "--ros-args",
        "-r", f"__ns:={args.namespace}",
        "-p", "frequency_hz:=47.0",
        "-p", "amplitude_n:=40.0",
        "-p", "rate_hz:=20.0",
    ]  # fmt: skip
    print(f"starting: {' '.join(command)}")
    process = subprocess.Popen(command)
    received: list[DriveCommand] = []
    try:
        with rclpy.init():
            node = rclpy.create_node("demo_probe")
            qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
            topic = f"{args.namespace}/drive/command"
            node.create_subscription(DriveCommand, topic, received.append, qos)
            deadline = time.monotonic() + args.seconds + 10.0
            first: float | None = None
            while time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.1)
                if received and first is None:
                    first = time.monotonic()
                if first is not None and time.monotonic() - first >= args.seconds:
                    break
            node.destroy_node()
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=10)

    if not received:
        print(f"FAILED: no drive command received on {args.namespace}/drive/command")
        return 1
    last = received[-1]
    summary = {
        "topic": f"{args.namespace}/drive/command",
        "messages": len(received),
        "frequency_hz": last.frequency_hz,
        "amplitude_n": last.amplitude_n,
        "publisher_exit_code": process.returncode,
    }
    (args.output / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"received {len(received)} DriveCommand messages on {summary['topic']}")
    print(f"  last: {last.frequency_hz} Hz, {last.amplitude_n} N, enabled={last.enabled}")
    print(f"  publisher stopped cleanly: exit {process.returncode}")
    print(f"summary written to {args.output / 'summary.json'}")
    return 0 if process.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
