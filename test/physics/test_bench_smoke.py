"""The benchmark script still runs (``--quick``); its timings are not checked here."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def test_benchmark_quick_run_writes_its_report(tmp_path: Path) -> None:
    report = tmp_path / "bench.md"
    completed = subprocess.run(
        [
            sys.executable,
            str(REPO / "bench" / "bench_physics.py"),
            "--quick",
            "--output",
            str(report),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert completed.returncode == 0, completed.stderr[-2000:]
    text = report.read_text(encoding="utf-8")
    assert text.startswith("### Physics core benchmark (--quick")
    for row in (
        "| exact engine (sharp) |",
        "| RK45, ode45 defaults (logistic), carrier only: baseline |",
        "| RK45, ode45 defaults (logistic) |",
        "| RK45, max step 1 ms (logistic) |",
        "| DOP853, rtol 1e-12 (sharp, carrier only): reference |",
        "| one part type |",
        "| all-distinct frictions |",
        "Fig. 9-style sweep",
        "| forgets past changes (engine) |",
        "| keeps every change (baseline) |",
    ):
        assert row in text
    # the many-parts rows carry their ratio to the baseline timed in turn with them
    header = next(line for line in text.splitlines() if line.startswith("| parts |"))
    assert "| vs RK45-default |" in header
    for label in ("| one part type |", "| all-distinct frictions |"):
        row = next(line for line in text.splitlines() if line.startswith(label))
        ratio, at_issue_speed = float(row.split("|")[4]), float(row.split("|")[5])
        assert ratio > 0.0
        assert at_issue_speed == pytest.approx(150.0 * ratio, rel=0.01)
    # the engine agrees with the DOP853 reference to round-off in every case table
    engine_rows = [line for line in text.splitlines() if line.startswith("| exact engine")]
    assert len(engine_rows) == 2
    for line in engine_rows:
        error = float(line.split("|")[5])
        assert error < 1e-9


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (
            ["--against", "no-such-rev"],
            "--against 'no-such-rev' is not a commit of this repository",
        ),
        (["--rounds", "0"], "--rounds must be at least 1, got 0"),
    ],
)
def test_the_engine_ab_refuses_a_bad_argument_by_name(arguments: list[str], message: str) -> None:
    completed = subprocess.run(
        [sys.executable, str(REPO / "bench" / "bench_engine_ab.py"), *arguments],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert completed.returncode == 2
    assert message in completed.stderr
    assert "Traceback" not in completed.stderr
