"""The README's node tables and the node catalogue cannot drift from the code."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ros_test_tools import console_scripts

from feeder_ros.nodes.catalog import NODE_MODULES, node_interfaces

REPO = Path(__file__).resolve().parents[1]


def test_catalogue_lists_exactly_the_installed_node_executables() -> None:
    installed = {
        target.split(":")[0]: exe
        for exe, target in console_scripts().items()
        if target.startswith("feeder_ros.nodes.")
    }
    assert set(NODE_MODULES) == set(installed)
    for interface in node_interfaces():
        module = next(m for m, exe in installed.items() if exe == interface.executable)
        assert module in NODE_MODULES


def test_readme_node_tables_are_current() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "feeder_ros.docgen", "--check", str(REPO / "README.md")],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, (
        "README is stale; run python -m feeder_ros.docgen README.md\n"
        + (result.stdout + result.stderr)
    )
