"""Test-session set-up shared by every test.

DDS isolation: before anything can initialise rclpy, the session claims a ROS domain id that no
other test session on this machine holds (a lock file per id) and limits discovery to localhost.
Every process the tests start inherits both, so parallel runs never see each other's nodes.

Ctrl-C: a session started as a background job of a non-interactive shell (``make test &`` in a
script, a CI runner's job) has SIGINT ignored, and every process it starts inherits that: the
tests that stop a node, ``feeder cell`` or a sweep with Ctrl-C (SIGINT) would see it ignored. The
session handles SIGINT again, so that its children start with the default disposition.
"""

from __future__ import annotations

import atexit
import fcntl
import os
import random
import signal
import sys
from pathlib import Path
from typing import IO

import pytest

TEST_DIR = Path(__file__).resolve().parent
REPO = TEST_DIR.parent
sys.path.insert(0, str(TEST_DIR))  # the helper modules next to this file

pytest_plugins = ["hard_timeout"]  # a per-test limit that also ends a test stuck in numba code

# Domain ids usable with Fast DDS on Linux without port clashes: 1..101 (0 is everyone's default).
_DOMAIN_IDS = list(range(1, 102))
_domain_lock: IO[str] | None = None


def _claim_domain_id() -> int:
    global _domain_lock
    lock_dir = Path(os.environ.get("TMPDIR", "/tmp")) / "feeder_ros_test_domains"
    lock_dir.mkdir(exist_ok=True)
    candidates = _DOMAIN_IDS[:]
    random.Random(os.getpid()).shuffle(candidates)
    for domain_id in candidates:
        handle = (lock_dir / f"{domain_id}.lock").open("w")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _domain_lock = handle  # held (and the id reserved) until this process exits
        atexit.register(handle.close)
        return domain_id
    raise RuntimeError(f"all ROS domain ids {_DOMAIN_IDS[0]}..{_DOMAIN_IDS[-1]} are in use")


if "FEEDER_ROS_TEST_DOMAIN_ID" not in os.environ:
    os.environ["FEEDER_ROS_TEST_DOMAIN_ID"] = str(_claim_domain_id())
os.environ["ROS_DOMAIN_ID"] = os.environ["FEEDER_ROS_TEST_DOMAIN_ID"]
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.pop("ROS_LOCALHOST_ONLY", None)
os.environ.setdefault("MPLBACKEND", "Agg")
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)  # exec resets it to SIG_DFL


def pytest_report_header() -> str:
    return f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} discovery=LOCALHOST"


@pytest.fixture(scope="session")
def workspace() -> Path:
    """The colcon workspace built by `make workspace` (tools/build_workspace.sh)."""
    path = Path(os.environ.get("FEEDER_ROS_WORKSPACE", REPO / ".work" / "ws"))
    setup = path / "install" / "local_setup.sh"
    if not setup.exists():
        pytest.fail(f"no colcon workspace at {path}: run `make workspace` (make test does)")
    return path
