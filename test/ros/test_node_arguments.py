"""Bad ROS arguments to a node executable: refused with the reason, exit status 2, no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


@pytest.mark.parametrize("executable", ["platform_simulator", "drive_interface"])
@pytest.mark.parametrize("case", ["missing", "malformed"])
def test_an_unusable_params_file_is_refused_by_name(
    tmp_path: Path, executable: str, case: str
) -> None:
    params = tmp_path / f"{case}.yaml"
    if case == "malformed":
        params.write_text("a: [1, 2\nb: {\n")
    result = subprocess.run(
        [str(BIN / executable), "--ros-args", "--params-file", str(params)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert "refusing to start: failed to initialize rcl: Couldn't parse params file" in output
    assert str(params) in output
    assert "Traceback" not in output
