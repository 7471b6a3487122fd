"""The hard per-test limit (test/hard_timeout.py) ends a run stuck in compiled code."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import hard_timeout
from stuck_code import STUCK_SPIN_SOURCE

TEST_DIR = Path(__file__).resolve().parent

STUCK = (
    STUCK_SPIN_SOURCE
    + """

def test_fine():
    assert spin(np.array([-1.0, 0.0, 0.0, 0.0])) == 0


def test_stuck():
    spin(np.zeros(4))
"""
)


def _run(tmp_path: Path, limit: str) -> tuple[subprocess.CompletedProcess[str], Path, float]:
    (tmp_path / "test_stuck.py").write_text(textwrap.dedent(STUCK))
    log = tmp_path / "hang.log"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(TEST_DIR), env.get("PYTHONPATH", "")])
    env[hard_timeout.HARD_TIMEOUT_ENV] = limit
    env[hard_timeout.HANG_LOG_ENV] = str(log)
    command = [sys.executable, "-m", "pytest", "-q", "-p", "hard_timeout", "-p", "no:cacheprovider"]
    started = time.monotonic()
    done = subprocess.run(
        [*command, "test_stuck.py"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,  # without the watchdog the run never ends: this raises
    )
    return done, log, time.monotonic() - started


def test_a_test_stuck_in_compiled_code_ends_the_run_with_its_stacks(tmp_path: Path) -> None:
    done, log, elapsed = _run(tmp_path, "5")
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr)
    assert 5.0 <= elapsed < 120.0
    text = log.read_text()
    assert text.startswith("test_stuck.py::test_stuck: still running after 5 s;"), text
    line = textwrap.dedent(STUCK).splitlines().index("    spin(np.zeros(4))") + 1
    assert f'test_stuck.py", line {line} in test_stuck' in text, text  # the stuck call's frame
    assert "test_fine" not in text  # the finished test's entry was cleared


def test_a_bad_hard_limit_is_refused_before_any_test_runs(tmp_path: Path) -> None:
    done, log, _ = _run(tmp_path, "nan")
    assert done.returncode == 4, (done.returncode, done.stdout, done.stderr)  # usage error
    assert f"{hard_timeout.HARD_TIMEOUT_ENV}='nan': expected a positive number of s" in done.stderr
    assert not log.exists()
