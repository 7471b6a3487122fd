"""A node stopped while it is being built ends as a stopped node does (exit 0, quietly); an
error in its constructor with the context alive still ends it with the error."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

NODE = """
import sys

import rclpy
from rclpy.node import Node

from feeder_ros.nodes import runner


class Starting(Node):
    def __init__(self) -> None:
        if sys.argv[1] == "stopped":
            # what rclpy's signal thread does on SIGINT or SIGTERM: the context goes down while
            # the node is still being built (CI: a cell stopped a simulator still starting)
            rclpy.get_default_context().shutdown()
        else:
            raise RuntimeError("broken constructor")
        super().__init__("starting_probe")


sys.exit(runner.run_node(Starting, ["starting_probe"]))
"""


@pytest.mark.parametrize(("mode", "status"), [("stopped", 0), ("broken", 1)])
def test_a_stop_while_a_node_is_built_is_a_stop(tmp_path: Path, mode: str, status: int) -> None:
    script = tmp_path / "starting_node.py"
    script.write_text(textwrap.dedent(NODE))
    result = subprocess.run(
        [sys.executable, str(script), mode], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == status, result.stderr
    if mode == "stopped":
        assert result.stderr == ""  # no traceback, nothing refused
    else:
        assert "RuntimeError: broken constructor" in result.stderr
