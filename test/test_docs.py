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


def test_readme_pictures_exist_and_say_what_makes_them() -> None:
    """Every picture the README shows is in the repository, a 1280 px wide PNG (a browser
    window's width), with the command that makes it in its caption."""
    import re
    import struct

    pictures = re.findall(r"!\[([^\]]*)\]\(([^)]+)\)", (REPO / "README.md").read_text())
    assert pictures
    for caption, path in pictures:
        data = (REPO / path).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n", path
        width = struct.unpack(">I", data[16:20])[0]
        assert width == 1280, (path, width)
        assert "make " in caption, caption
