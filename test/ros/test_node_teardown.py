"""A node whose teardown hangs in compiled code still ends (``runner.TEARDOWN_LIMIT_S``)."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from stuck_code import STUCK_SPIN_SOURCE

NODE = (
    STUCK_SPIN_SOURCE
    + """
import sys

from rclpy.node import Node

from feeder_ros.nodes import runner

runner.TEARDOWN_LIMIT_S = 3.0
HANG = sys.argv[1] == "hang"


class Teardown(Node):
    def __init__(self) -> None:
        super().__init__("teardown_probe")
        self.create_timer(0.05, lambda: print("spinning", flush=True))

    def destroy_node(self) -> None:
        if HANG:
            spin(np.zeros(4))
        super().destroy_node()


sys.exit(runner.run_node(Teardown, ["teardown_probe"]))
"""
)


def _stop_with_sigterm(tmp_path: Path, mode: str) -> tuple[int, str]:
    script = tmp_path / "teardown_node.py"
    script.write_text(textwrap.dedent(NODE))
    process = subprocess.Popen(
        [sys.executable, str(script), mode],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()  # the node spins: its timer prints
        assert line.strip() == "spinning", line
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=120)  # without the watchdog "hang" never ends
        return process.returncode, err
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_a_teardown_stuck_in_compiled_code_ends_the_process_with_its_stack(
    tmp_path: Path,
) -> None:
    code, err = _stop_with_sigterm(tmp_path, "hang")
    assert code == 1
    assert "Timeout (0:00:03)!" in err
    assert "in destroy_node" in err  # the stuck call, named on stderr


def test_a_clean_teardown_exits_0_without_the_watchdog(tmp_path: Path) -> None:
    code, err = _stop_with_sigterm(tmp_path, "clean")
    assert code == 0, err
    assert "Timeout" not in err
