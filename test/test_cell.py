"""Cell descriptions and `feeder cell`: feeders side by side, clean shutdown, no orphans."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from ros_test_tools import DrainedProcess, probe_node, wait_until
from simulator_process import manual_cell_file
from stuck_code import TEARDOWN_TIMEOUT_TEXT, stuck_teardown_script

from feeder_ros.cell import CellError, load_cell, parameters_document
from feeder_ros.cli import cell as cell_command
from feeder_ros.cli.cell import node_executables
from feeder_ros.cli.main import main
from feeder_ros.msg import DriveCommand
from feeder_ros.nodes.manual_drive import COMMAND_QOS

BIN = Path(sys.executable).parent
CONFIG = Path(__file__).resolve().parents[1] / "config"


def _write(path: Path, cell: object) -> Path:
    path.write_text(yaml.safe_dump({"cell": cell}), encoding="utf-8")
    return path


def _two_feeders(tmp_path: Path) -> Path:
    return manual_cell_file(
        tmp_path / "cell.yaml", "test_cell", ["/side/feeder_a", "/side/feeder_b"]
    )


def test_the_shipped_cell_description_is_valid() -> None:
    cell = load_cell(CONFIG / "cell.yaml", node_executables())
    executables = {node.executable for node in cell.nodes}
    assert {"platform_simulator", "vehicle_estimator", "speed_monitor"} <= executables
    simulator = next(n for n in cell.nodes if n.executable == "platform_simulator")
    assert simulator.parameters["damping_ns_per_m"] == 200.0  # the realistic section
    assert simulator.parameters["feed_interval_s"] == 1.5  # the cell's own override
    drive = next(n for n in cell.nodes if n.executable == "drive_interface")
    assert drive.parameters["plant.damping_ns_per_m"] == 200.0  # nested override, flattened
    assert drive.parameters["plant.youngs_modulus_pa"] == 200e9  # from drive_interface.yaml


def test_parameters_document_is_keyed_by_fully_qualified_name(tmp_path: Path) -> None:
    cell = load_cell(_two_feeders(tmp_path), node_executables())
    document = yaml.safe_load(parameters_document(cell))
    assert set(document) == {
        "/side/feeder_a/platform_simulator",
        "/side/feeder_a/manual_drive",
        "/side/feeder_b/platform_simulator",
        "/side/feeder_b/manual_drive",
    }
    values = document["/side/feeder_b/platform_simulator"]["ros__parameters"]
    assert values["imu_rate_hz"] == 200.0
    assert values["damping_ns_per_m"] == 200.0


@pytest.mark.parametrize(
    ("cell", "needle"),
    [
        ({"feeders": []}, "cell.feeders must be a non-empty list"),
        ({"feeders": [{"namespace": "feeder", "nodes": {"manual_drive": {}}}]}, "'feeder'"),
        (
            {"feeders": [{"namespace": "/a", "nodes": {"teleporter": {}}}]},
            "nodes.teleporter: unknown node",
        ),
        (
            {
                "feeders": [
                    {"namespace": "/a", "nodes": {"manual_drive": {}}},
                    {"namespace": "/a", "nodes": {"manual_drive": {}}},
                ]
            },
            "namespace /a is used twice",
        ),
        (
            {
                "feeders": [
                    {"namespace": "/a", "nodes": {"manual_drive": {"params_file": "no.yaml"}}}
                ]
            },
            "cannot read params_file",
        ),
        (
            {
                "feeders": [
                    {
                        "namespace": "/a",
                        "nodes": {"manual_drive": {"parameters": {"rate_hz": [{"x": 1}]}}},
                    }
                ]
            },
            "parameters.rate_hz=[{'x': 1}] is not a value",
        ),
        ({"use_sim_time": "yes", "feeders": []}, "use_sim_time='yes'"),
    ],
)
def test_bad_descriptions_are_refused_naming_the_entry(
    tmp_path: Path, cell: dict[str, object], needle: str
) -> None:
    with pytest.raises(CellError) as error:
        load_cell(_write(tmp_path / "bad.yaml", cell), node_executables())
    assert needle in str(error.value)


def _children(pid: int) -> set[int]:
    result = subprocess.run(
        ["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True
    )
    return {int(line) for line in result.stdout.split()}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().split()[2] != "Z"


def _describe(pids: set[int]) -> str:
    """What each process still alive is and where it waits (for a failure's message)."""
    lines = []
    for pid in sorted(pids):
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            state = Path(f"/proc/{pid}/stat").read_text().split()[2]
            waits = Path(f"/proc/{pid}/wchan").read_text()
        except OSError:
            continue  # ended meanwhile
        lines.append(f"pid {pid} state {state} waits in {waits or '-'}: {command}")
    return "\n".join(lines)


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm", "sigkill"])
def test_cell_runs_feeders_side_by_side_and_leaves_no_orphans(tmp_path: Path, how: str) -> None:
    cell_file = _two_feeders(tmp_path)
    process = DrainedProcess([str(BIN / "feeder"), "cell", "--config", str(cell_file)])
    try:
        with probe_node() as node:

            def all_up() -> bool:
                names = set(node.get_node_names_and_namespaces())
                return all(
                    (name, ns) in names
                    for ns in ("/side/feeder_a", "/side/feeder_b")
                    for name in ("platform_simulator", "manual_drive")
                )

            assert wait_until(all_up, 30.0), node.get_node_names_and_namespaces()

            def topics_up() -> bool:  # a node shows up before its publishers are discovered
                topics = dict(node.get_topic_names_and_types())
                return "/side/feeder_a/drive/command" in topics and "/side/feeder_b/imu" in topics

            assert wait_until(topics_up, 15.0), node.get_topic_names_and_types()
        children = _children(process.pid)
        assert len(children) == 4
        if how in ("ctrl-c", "sigterm"):  # SIGTERM: as a service manager (or the demo) stops it
            process.send_signal(signal.SIGINT if how == "ctrl-c" else signal.SIGTERM)
            process.wait(timeout=30)
            output = process.output()
            assert process.returncode == 0, output
            assert "[cell] stopping" in output
        else:
            process.kill()  # the supervisor dies without cleaning up ...
            process.wait(timeout=10)
        # ... and still no node survives it
        gone = wait_until(lambda: not any(_alive(pid) for pid in children), 30.0)
        assert gone, _describe(children) + "\n" + process.output()
    finally:
        if process.poll() is None:
            process.kill()


def test_composed_cell_runs_every_node_in_one_process(tmp_path: Path) -> None:
    cell_file = _two_feeders(tmp_path)
    process = subprocess.Popen(
        [str(BIN / "feeder"), "cell", "--composed", "--config", str(cell_file)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        with probe_node() as node:

            def up() -> bool:
                names = set(node.get_node_names_and_namespaces())
                return ("platform_simulator", "/side/feeder_b") in names

            assert wait_until(up, 30.0)
        assert _children(process.pid) == set()  # no child processes: all nodes inside
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=30)
        assert process.returncode == 0, output
    finally:
        if process.poll() is None:
            process.kill()


COMPOSED_CELL_WITH_A_STUCK_TEARDOWN = stuck_teardown_script(
    """
from feeder_ros.cli.main import main
from feeder_ros.nodes import manual_drive

manual_drive.NODE_CLASS.destroy_node = stuck
sys.exit(main(["cell", "--composed", "--config", sys.argv[1], "--duration", "3"]))
"""
)


def test_a_composed_cell_whose_teardown_hangs_still_ends(tmp_path: Path) -> None:
    script = tmp_path / "stuck_cell.py"
    script.write_text(COMPOSED_CELL_WITH_A_STUCK_TEARDOWN)
    result = subprocess.run(
        [sys.executable, str(script), str(_two_feeders(tmp_path))],
        capture_output=True,
        text=True,
        timeout=120,  # without the watchdog: never ends
    )
    assert result.returncode == 1, result.stdout + result.stderr
    assert "[cell] composing /side/feeder_b/manual_drive" in result.stdout
    assert TEARDOWN_TIMEOUT_TEXT in result.stderr
    assert "in stuck" in result.stderr  # the stuck call, named on stderr


CHILD_WITH_A_STUCK_TEARDOWN = """
import os
import sys

if os.path.basename(sys.argv[0]) == "manual_drive":  # only the cell's manual_drive child
    exec(compile(open(os.environ["STUCK_SCRIPT"]).read(), "stuck_script", "exec"))
"""


def test_a_cell_waits_out_a_nodes_stuck_teardown_and_names_it(tmp_path: Path) -> None:
    # the manual_drive process's destroy_node spins for good (as Fast DDS's participant
    # teardown once did); its own watchdog ends it, and the cell says which node failed
    stuck = tmp_path / "stuck.py"
    stuck.write_text(
        stuck_teardown_script(
            "from feeder_ros.nodes import manual_drive\n"
            "manual_drive.NODE_CLASS.destroy_node = stuck\n"
        )
    )
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(CHILD_WITH_A_STUCK_TEARDOWN)
    env = dict(os.environ, PYTHONPATH=str(site), STUCK_SCRIPT=str(stuck))
    config = manual_cell_file(tmp_path / "cell.yaml", "stuck_cell", ["/stuck/feeder_1"])
    process = DrainedProcess([str(BIN / "feeder"), "cell", "--config", str(config)], env=env)
    try:
        with probe_node() as node:
            # its commands on the wire: the node is built and spinning (a node shows in the
            # graph while it is still being built, and a stop then never reaches its teardown)
            commands: list[DriveCommand] = []
            node.create_subscription(
                DriveCommand, "/stuck/feeder_1/drive/command", commands.append, COMMAND_QOS
            )
            assert wait_until(lambda: len(commands) > 0, 60.0), process.output()
        start = time.monotonic()
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)
        took = time.monotonic() - start
        output = process.output()
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 1, output
    assert "[cell] /stuck/feeder_1/manual_drive ended its stop with exit status 1" in output
    assert TEARDOWN_TIMEOUT_TEXT in output  # its own watchdog ended it ...
    assert "in stuck" in output  # ... with its stacks
    assert "killed" not in output
    assert "platform_simulator ended" not in output
    assert took < cell_command.STOP_LIMIT_S, (took, output)  # 3 s limit here: never killed


def test_the_cell_outwaits_a_nodes_own_teardown_limit() -> None:
    from feeder_ros.nodes import runner

    spin_stop_s = runner.StopOnShutdown.shutdown_wait_s + 1.0  # a callback in flight
    assert runner.TEARDOWN_LIMIT_S + spin_stop_s <= cell_command.STOP_LIMIT_S


def test_cell_refuses_a_bad_description_before_starting_anything(tmp_path: Path) -> None:
    bad = _write(tmp_path / "bad.yaml", {"feeders": [{"namespace": "/a", "nodes": {"x": {}}}]})
    result = subprocess.run(
        [str(BIN / "feeder"), "cell", "--config", str(bad)], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert "nodes.x: unknown node" in result.stderr


@pytest.mark.parametrize("duration", ["inf", "nan", "0", "-3"])
def test_a_duration_that_never_ends_or_never_starts_is_refused(
    duration: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["cell", "--duration", duration, "--list"])
    assert exit_info.value.code == 2
    assert f"argument --duration: {duration!r}" in capsys.readouterr().err


def test_list_prints_command_lines_that_run_on_the_written_parameters(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = _two_feeders(tmp_path)
    cell = load_cell(config, node_executables())
    params = tmp_path / "cell_params.yaml"
    assert main(["cell", "--config", str(config), "--list", "--params-out", str(params)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(cell.nodes)
    for line, node in zip(lines, cell.nodes, strict=True):
        command = shlex.split(line)
        assert command == [str(node.executable), *node.ros_arguments(params)]
    written = yaml.safe_load(params.read_text())
    assert written == yaml.safe_load(parameters_document(cell))
    assert set(written) == {node.fully_qualified_name for node in cell.nodes}

    # without --params-out the file is printed after the commands, under the name they use
    assert main(["cell", "--config", str(config), "--list"]) == 0
    out = capsys.readouterr().out
    commands, document = out.split("# parameters.yaml (save this as parameters.yaml", 1)
    assert all(line.endswith("--params-file parameters.yaml") for line in commands.splitlines())
    assert yaml.safe_load(document.split("\n", 1)[1]) == written

    assert main(["cell", "--params-out", str(params)]) == 2
    assert "--params-out goes with --list" in capsys.readouterr().err
