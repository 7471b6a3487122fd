"""The test session's children handle Ctrl-C however the session was started (see conftest)."""

from __future__ import annotations

import subprocess
import sys

CHECK = (
    "import signal, sys; "
    "sys.exit(0 if signal.getsignal(signal.SIGINT) is signal.default_int_handler else 3)"
)


def test_a_child_python_turns_ctrl_c_into_keyboard_interrupt() -> None:
    """Python installs its KeyboardInterrupt handler only if SIGINT is not ignored at start: a
    session run as a background job must not hand its ignored SIGINT to the nodes, ``feeder
    cell`` and sweeps that the tests stop with Ctrl-C."""
    child = subprocess.run([sys.executable, "-c", CHECK], timeout=120)
    assert child.returncode == 0
