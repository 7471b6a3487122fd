"""A hard per-test time limit that also ends a test stuck in compiled code (a pytest plugin).

pytest-timeout's limit (``timeout`` in pyproject.toml) is a SIGALRM handler, and Python runs
signal handlers only between bytecodes: a test stuck in a numba nopython loop (which holds the GIL)
never gets back there, and the run would hang until CI's own limit. faulthandler's watchdog is a C
thread that needs no GIL: past the hard limit it writes the test's id and every thread's stack to
the hang log and ends the process with status 1 (``make pytest`` then prints the log).

Environment: ``FEEDER_ROS_TEST_HARD_TIMEOUT_S`` (default 900 s, three times pytest-timeout's
limit), ``FEEDER_ROS_TEST_HANG_LOG`` (default ``<rootdir>/.work/test-hang.log``).
"""

from __future__ import annotations

import faulthandler
import os
from collections.abc import Generator
from pathlib import Path
from typing import IO

import pytest

HARD_TIMEOUT_ENV = "FEEDER_ROS_TEST_HARD_TIMEOUT_S"
HANG_LOG_ENV = "FEEDER_ROS_TEST_HANG_LOG"
DEFAULT_HARD_TIMEOUT_S = 900.0

_log: IO[str] | None = None


def _limit_s() -> float:
    text = os.environ.get(HARD_TIMEOUT_ENV, str(DEFAULT_HARD_TIMEOUT_S))
    try:
        limit = float(text)
    except ValueError:
        limit = float("nan")
    if not limit > 0.0 or limit == float("inf"):
        raise pytest.UsageError(f"{HARD_TIMEOUT_ENV}={text!r}: expected a positive number of s")
    return limit


def pytest_configure(config: pytest.Config) -> None:
    global _log
    _limit_s()  # refuse a bad limit before any test runs
    path = Path(os.environ.get(HANG_LOG_ENV, config.rootpath / ".work" / "test-hang.log"))
    path.parent.mkdir(parents=True, exist_ok=True)
    _log = path.open("w")  # emptied: a log left by an earlier run would mislead


def pytest_unconfigure(config: pytest.Config) -> None:
    global _log
    if _log is not None:
        _log.close()
        _log = None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Generator[None, None, None]:
    log = _log
    if log is None:
        yield
        return
    limit = _limit_s()
    log.seek(0)
    log.truncate()
    log.write(f"{item.nodeid}: still running after {limit:g} s; the stacks of all threads:\n")
    log.flush()
    faulthandler.dump_traceback_later(limit, exit=True, file=log)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        log.seek(0)
        log.truncate()
        log.flush()
