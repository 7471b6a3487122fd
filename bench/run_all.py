#!/usr/bin/env python3
"""`make bench`: run every benchmark in this directory and collect their tables in one report.

Each benchmark measures its baseline in the same run and prints ratios against it; this script
runs them one after another (never in parallel: they time themselves) and writes the combined
markdown to bench/results/latest.md, ready to paste into BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = [
    ("Physics core (issue 3)", "bench_physics.py"),
    ("The exact engine against the one before its cut into steps (issue 30)", "bench_engine_ab.py"),
    ("Sensorless estimator against ground truth (issue 4)", "eval_estimator.py"),
    ("The estimator on mismatched feeders, before and after calibration", "eval_mismatch.py"),
    ("Live nodes over DDS (issue 4)", "bench_live.py"),
    ("Bag decoding and feeder analyze (issue 6)", "bench_bag.py"),
    ("Parts on request: feed_parts against continuous running (issue 34)", "bench_feed_parts.py"),
    ("Robust design search against one-by-one evaluation (issue 32)", "bench_robust_design.py"),
]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="short smoke runs")
    args = parser.parse_args()
    results = HERE / "results"
    results.mkdir(exist_ok=True)
    sections = []
    status = 0
    for title, script in BENCHMARKS:
        if not (HERE / script).exists():
            continue
        output = results / f"{Path(script).stem}.md"
        command = [sys.executable, str(HERE / script), "--output", str(output)]
        if args.quick:
            command.append("--quick")
        print(f"== {title}: {' '.join(command)}", flush=True)
        started = time.perf_counter()
        code = subprocess.call(command)
        print(f"== {title}: exit {code} after {time.perf_counter() - started:.1f} s", flush=True)
        status = status or code
        if output.exists():
            sections.append(f"## {title}\n\n`python bench/{script}`\n\n{output.read_text()}")
    (results / "latest.md").write_text("\n".join(sections), encoding="utf-8")
    print(f"combined report: {results / 'latest.md'}")
    return status


if __name__ == "__main__":
    sys.exit(main())
