"""Both install paths: the project venv (pip + rosidl into the venv) and a colcon workspace.

The workspace test resolves every node executable the way `ros2 run feeder_ros <exe>` does
(ament index -> <prefix>/lib/feeder_ros/<exe>), starts it with --ros-args and checks the effect
of a namespace, a remapping and a parameter on the live ROS graph.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
from rcl_interfaces.srv import GetParameters
from ros_test_tools import (
    call,
    console_scripts,
    node_executables,
    probe_node,
    running,
    sourced_environment,
    wait_until,
)

REPO = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.executable).parent

IMPORT_CHECK = (
    "import feeder_ros.msg as m, feeder_ros.srv as s; "
    "from feeder_ros.msg import DriveCommand; "
    "print(m.__file__); print(s.__file__); print(DriveCommand(frequency_hz=47.0).frequency_hz)"
)


def test_plain_venv_path_has_interfaces_and_console_scripts(tmp_path: Path) -> None:
    for executable in console_scripts():
        assert (VENV_BIN / executable).is_file(), f"{executable} not on the venv's PATH"
    # from a neutral directory, so that nothing but the install makes the import work
    result = subprocess.run(
        [str(VENV_BIN / "python"), "-c", IMPORT_CHECK],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=True,
    )
    msg_file, srv_file, value = result.stdout.split()
    site = Path(sysconfig.get_paths()["purelib"]).resolve()
    assert Path(msg_file).resolve().is_relative_to(site)
    assert Path(srv_file).resolve().is_relative_to(site)
    assert value == "47.0"
    help_text = subprocess.run(
        [str(VENV_BIN / "feeder"), "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert "sim" in help_text


def test_workspace_path_layout(workspace: Path, tmp_path: Path) -> None:
    env = sourced_environment(workspace / "install" / "local_setup.sh")
    prefix = workspace / "install" / "feeder_ros"
    assert str(prefix) in env["AMENT_PREFIX_PATH"].split(os.pathsep)
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / "feeder_ros"
    assert marker.is_file()
    assert (prefix / "share" / "feeder_ros" / "package.xml").is_file()
    for executable in console_scripts():
        path = prefix / "lib" / "feeder_ros" / executable
        assert path.is_file(), f"{path} missing"
        assert os.access(path, os.X_OK), f"{path} not executable"
    result = subprocess.run(
        [sys.executable, "-c", IMPORT_CHECK],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    msg_file, srv_file, _ = result.stdout.split()
    assert Path(msg_file).is_relative_to(prefix), msg_file
    assert Path(srv_file).is_relative_to(prefix), srv_file


def _ros2_run_path(env: dict[str, str], executable: str) -> Path:
    """What `ros2 run feeder_ros <executable>` would execute (ros2pkg's get_executable_paths)."""
    from ament_index_python.packages import get_package_prefix

    saved = os.environ.get("AMENT_PREFIX_PATH")
    os.environ["AMENT_PREFIX_PATH"] = env["AMENT_PREFIX_PATH"]
    try:
        base = Path(get_package_prefix("feeder_ros")) / "lib" / "feeder_ros"
    finally:
        if saved is None:
            del os.environ["AMENT_PREFIX_PATH"]
        else:
            os.environ["AMENT_PREFIX_PATH"] = saved
    candidates = [p for p in base.iterdir() if p.is_file() and os.access(p, os.X_OK)]
    matches = [p for p in candidates if p.name == executable]
    assert len(matches) == 1, f"ros2 run would not find {executable} in {base}"
    return matches[0]


def test_every_node_executable_is_tested() -> None:
    assert node_executables(), "setup.py installs no node executable"


@pytest.mark.parametrize("executable", node_executables())
def test_ros2_run_resolves_and_honours_ros_args(workspace: Path, executable: str) -> None:
    env = sourced_environment(workspace / "install" / "local_setup.sh")
    path = _ros2_run_path(env, executable)
    assert path.parent == workspace / "install" / "feeder_ros" / "lib" / "feeder_ros"

    module_name = console_scripts()[executable].split(":")[0]
    interface = importlib.import_module(module_name).INTERFACE
    topic = (interface.publishes + interface.subscribes)[0]
    namespace = "/cell_a/feeder_7"
    remapped = f"remapped/{topic.name.replace('/', '_')}"
    node_name = f"{interface.node_name}_renamed"
    command = [
        str(path),
        "--ros-args",
        "-r", f"__ns:={namespace}",
        "-r", f"__node:={node_name}",
        "-r", f"{topic.name}:={remapped}",
        "-p", "use_sim_time:=true",
    ]  # fmt: skip
    with running(command, env=env) as process, probe_node() as probe:

        def node_visible() -> bool:
            return (node_name, namespace) in probe.get_node_names_and_namespaces()

        assert wait_until(node_visible, 20.0), process.poll()
        topics = dict(probe.get_topic_names_and_types())

        def topic_visible() -> bool:
            topics.update(probe.get_topic_names_and_types())
            return f"{namespace}/{remapped}" in topics

        assert wait_until(topic_visible, 10.0), sorted(topics)
        assert topics[f"{namespace}/{remapped}"] == [topic.type]
        assert f"{namespace}/{topic.name}" not in topics  # remapped away

        answer = call(
            probe,
            GetParameters,
            f"{namespace}/{node_name}/get_parameters",
            GetParameters.Request(names=["use_sim_time"]),
        )
        assert answer.values[0].bool_value is True
        assert process.poll() is None, "node exited early"
    assert process.returncode == 0, process.output()
