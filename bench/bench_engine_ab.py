"""The exact engine of this checkout against another commit's, timed in the same run.

A refactor of the engine must keep its speed (issue 30: "within noise of today's engine measured
in the same run"). This exports ``feeder_ros`` of ``--against`` (a commit, default the engine
before issue 30's cut) with ``git archive`` into a temporary directory, then times each case in
fresh processes, alternating this checkout and that commit round after round, each side with its
own numba cache (compiled by an untimed first call): a process keeps its best call (of at least
5, and of at least half a second of calls). A case compares the two sides' medians over the
rounds, and their fastest processes: on this machine fresh processes of one engine land in two
speed modes (the same 0.4 N case took 4.7 or 7.5 ms per call, process by process, within an
hour), so a median can compare one side's fast processes with the other's slow ones, while the
fastest process of each side is its fast mode (if it got one: more rounds make that likelier).
The cases use only the public ``simulate`` API, which both sides have.

Usage: ``python bench/bench_engine_ab.py [--against REV] [--rounds N] [--quick] [--output FILE]``
(about 7 minutes at 6 rounds, most of it compiling both engines). Prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BEFORE_ISSUE_30 = "1b1ca91"  # the last commit with the engine as one module (sharp_solver.py)

CASES = {
    "1 part, A = 40 N, 10 s, output 1 ms (global loop)": ("one", "40", "10"),
    "1 part, A = 0.4 N, 100 s, output 1 ms (global loop)": ("one", "0.4", "100"),
    "1000 all-distinct parts, A = 40 N, 5 s, output 100 Hz (group march)": (
        "distinct",
        "1000",
        "5",
    ),
}

# run in a fresh process (python -P: no current directory on the path) with PYTHONPATH at one
# side's tree; prints its best call in s and the file the engine was imported from
TIMING = """
import json, sys, time
import numpy as np
import feeder_ros.physics.simulation as simulation
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import PartSpec, simulate

def one(amplitude, duration):
    params = FeederParameters(drive_amplitude_n=float(amplitude))
    return lambda: simulate(params, float(duration), 1000.0)

def distinct(count, duration):
    count, duration = int(count), float(duration)
    rng = np.random.default_rng(1)
    mu_s = rng.uniform(0.15, 0.3, count)
    mu_d = mu_s * rng.uniform(0.4, 0.9, count)
    parts = tuple(
        PartSpec(position_m=0.25 * i / count, static_friction=float(s), kinetic_friction=float(d))
        for i, (s, d) in enumerate(zip(mu_s, mu_d))
    )
    params = FeederParameters(drive_amplitude_n=40.0)
    return lambda: simulate(params, duration, 100.0, parts=parts).events.arrays()

kind, *arguments = sys.argv[1:]
call = {"one": one, "distinct": distinct}[kind](*arguments)
call()
best, calls, spent = float("inf"), 0, 0.0
while calls < 5 or spent < 0.5:  # a short case is called until it has run for half a second
    started = time.perf_counter()
    call()
    took = time.perf_counter() - started
    best, calls, spent = min(best, took), calls + 1, spent + took
print(json.dumps({"best_s": best, "source": simulation.__file__}))
"""


def export(rev: str, into: Path) -> Path:
    """``feeder_ros`` of commit ``rev`` under ``into``; returns the directory to put on the path."""
    archive = into / "tree.tar"
    with archive.open("wb") as out:
        subprocess.run(["git", "archive", rev, "feeder_ros"], cwd=REPO, stdout=out, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into / "tree", filter="data")
    return into / "tree"


def time_once(tree: Path, cache: Path, case: tuple[str, ...]) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(cache), NUMBA_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, "-P", "-c", TIMING, *case],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"case {case!r} failed under {tree}:\n{done.stderr}")
    result = json.loads(done.stdout)
    if not Path(result["source"]).resolve().is_relative_to(tree.resolve()):
        raise RuntimeError(f"the engine under test came from {result['source']}, not from {tree}")
    return float(result["best_s"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default=BEFORE_ISSUE_30, help="the commit to compare with")
    parser.add_argument("--rounds", type=int, default=6, help="alternating rounds per case")
    parser.add_argument("--quick", action="store_true", help="one round (a smoke run)")
    parser.add_argument("--output", type=Path, help="also write the markdown report here")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds = 1
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, got {args.rounds}")
    known = subprocess.run(
        ["git", "rev-parse", "--verify", "--quiet", f"{args.against}^{{commit}}"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    if known.returncode != 0 or args.against.startswith("-"):  # not an option of git's
        parser.error(f"--against {args.against!r} is not a commit of this repository")
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
    ).stdout.strip()
    changed = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no", "feeder_ros"],
        cwd=REPO,
        capture_output=True,
        text=True,
    ).stdout.strip()
    head = f"{head or 'unknown'}{' with uncommitted changes' if changed else ''}"
    lines = [
        f"#### The engine of this checkout ({head}) against {args.against}",
        "",
        f"`python bench/bench_engine_ab.py --against {args.against} --rounds {args.rounds}`: one "
        "thread, fresh processes alternating old and new, each its best call (of at least 5 and "
        "0.5 s); 'new / old' is the ratio of the medians over the rounds, and of the fastest "
        "processes (each side's fast mode).",
        "",
        "| case | old [ms] per round | new [ms] per round | new / old, medians | fastest |",
        "| --- | --- | --- | ---: | ---: |",
    ]
    with tempfile.TemporaryDirectory(prefix="engine-ab-") as tmp:
        work = Path(tmp)
        sides = {
            "old": (export(args.against, work), work / "cache-old"),
            "new": (REPO, work / "cache-new"),
        }
        for label, case in CASES.items():
            times: dict[str, list[float]] = {"old": [], "new": []}
            for _ in range(args.rounds):
                for side, (tree, cache) in sides.items():
                    times[side].append(time_once(tree, cache, case))
            ratio = statistics.median(times["new"]) / statistics.median(times["old"])
            fastest = min(times["new"]) / min(times["old"])
            lines.append(
                f"| {label} | {' / '.join(f'{t * 1e3:.3g}' for t in times['old'])} | "
                f"{' / '.join(f'{t * 1e3:.3g}' for t in times['new'])} | {ratio:.3f} | "
                f"{fastest:.3f} |"
            )
            print(f"done: {label}", file=sys.stderr, flush=True)
    lines.append("")
    report = "\n".join(lines)
    print(report)
    if args.output is not None:
        args.output.write_text(report + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
