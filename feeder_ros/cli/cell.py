"""``feeder cell``: bring up a feeder cell from its description (``config/cell.yaml``).

Each node runs as its own process, like a launch file (default), or all in one process
(``--composed``). Ctrl-C or SIGTERM, the normal end of a running cell, stops every node cleanly
(exit status 0); a node that dies stops the cell (1); children also get SIGTERM if this process
itself is killed, so no node is left orphaned.
``--list`` prints each node's command line and the cell's parameter file instead (written to
``--params-out FILE`` for the printed commands to use, or printed after them).
"""

from __future__ import annotations

import argparse
import ctypes
import faulthandler
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from feeder_ros.atomic_files import atomic_text
from feeder_ros.cell import CellDescription, CellError, load_cell, parameters_document
from feeder_ros.cli.arguments import positive_float
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.outputs import check_output_file, output_path
from feeder_ros.cli.view import DEFAULT_PORT, port_number

if TYPE_CHECKING:
    from rclpy.context import Context

HELP = "start a feeder cell (all its nodes) from a cell description; Ctrl-C stops it"
EPILOG = """\
Ctrl-C: the normal way to stop a running cell (SIGTERM too): every node started so far is
stopped, then exit status 0. A node whose teardown hangs in the middleware ends itself 5 s
after its spin stopped (--composed: the process), one still running 8 s after the stop is
killed: exit status 1, and the node named. A node that exits by itself stops the cell: exit
status 1. A Ctrl-C before the cell starts (its '[cell] NAME: N nodes' line)
cuts the command short: exit status 130.

--foxglove runs 'feeder view' beside the nodes (its own process): every topic of the cell on
ws://127.0.0.1:8765 (or PORT) for Foxglove; if it cannot start (the port taken), the cell stops
with exit status 1.

examples:
  # the demo cell of config/cell.yaml, each node its own process, until Ctrl-C
  feeder cell
  # the same with its live view for Foxglove on ws://127.0.0.1:8765
  feeder cell --foxglove
  # every node in this one process, for one minute
  feeder cell --composed --duration 60
  # the nodes' command lines, their parameters written to parameters.yaml
  feeder cell --list --params-out parameters.yaml"""
CELL_FILE = "cell.yaml"
#: seconds the cell waits for its nodes to end after it interrupted them, before it kills them:
#: a node stops spinning within ~1 s (``runner.StopOnShutdown``) and bounds its own teardown by
#: ``runner.TEARDOWN_LIMIT_S`` (5 s, not imported here: rclpy takes seconds to load), so a node
#: stuck in the middleware ends by its own watchdog, its stacks printed, before this kill
STOP_LIMIT_S = 8.0
_PR_SET_PDEATHSIG = 1


def default_cell_path() -> Path:
    source = Path(__file__).resolve().parents[2] / "config" / CELL_FILE
    if source.is_file():
        return source
    installed = Path(sys.prefix) / "share" / "feeder_ros" / "config" / CELL_FILE
    if installed.is_file():
        return installed
    raise CommandError(f"cannot find {CELL_FILE}; pass --config FILE")


def node_executables() -> frozenset[str]:
    from feeder_ros.nodes.catalog import NODE_MODULES

    return frozenset(module.rsplit(".", 1)[-1] for module in NODE_MODULES)


def executable_path(name: str) -> Path:
    """Where the executable is: the ament index (a ROS workspace) first, then this venv."""
    try:
        from ament_index_python.packages import get_package_prefix

        candidate = Path(get_package_prefix("feeder_ros")) / "lib" / "feeder_ros" / name
        if candidate.is_file():
            return candidate
    except (ImportError, LookupError, OSError):  # not installed, not found, no AMENT_PREFIX_PATH
        pass
    candidate = Path(sys.executable).parent / name
    if candidate.is_file():
        return candidate
    found = shutil.which(name)
    if found is None:
        raise CommandError(f"executable {name!r} not found (run `make install`)")
    return Path(found)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=Path, help=f"cell description (default: {CELL_FILE})")
    parser.add_argument("--composed", action="store_true", help="run all nodes in this one process")
    parser.add_argument(
        "--duration",
        type=positive_float,
        help="stop after this many seconds (default: until Ctrl-C)",
    )
    parser.add_argument(
        "--foxglove",
        nargs="?",
        const=DEFAULT_PORT,
        type=port_number,
        metavar="PORT",
        help=f"also serve the cell's topics live to Foxglove on ws://127.0.0.1:PORT (default "
        f"{DEFAULT_PORT}; see feeder view --help)",
    )
    parser.add_argument(
        "--list",
        action="store_true",
        help="print each node's command line and the cell's parameters (YAML), then exit",
    )
    parser.add_argument(
        "--params-out",
        type=output_path,
        metavar="FILE",
        help="--list: write the cell's parameters here, for the printed commands to use",
    )


def _die_with_parent() -> None:  # runs in the child between fork and exec
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


Children = list[tuple[str, "subprocess.Popen[bytes]"]]  # (name in messages, process)
Extras = Sequence[tuple[str, list[str]]]  # processes beside the nodes: (name, command line)


def _start(name: str, command: list[str], children: Children) -> None:
    print(f"[cell] starting {name}", flush=True)
    children.append((name, subprocess.Popen(command, preexec_fn=_die_with_parent)))


def _one_exited(children: Children) -> bool:
    """Whether a child has exited by itself (said on stdout): the cell then stops."""
    for name, process in children:
        code = process.poll()
        if code is not None:
            print(f"[cell] {name} exited with {code}: stopping the cell", flush=True)
            return True
    return False


def run_processes(
    cell: CellDescription, parameters_file: Path, duration: float | None, extras: Extras = ()
) -> int:
    children: Children = []
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)  # like Ctrl-C
    status = 0
    try:
        for node in cell.nodes:
            command = [str(executable_path(node.executable)), *node.ros_arguments(parameters_file)]
            _start(node.fully_qualified_name, command, children)
        for name, command in extras:
            _start(name, command, children)
        deadline = None if duration is None else time.monotonic() + duration
        while deadline is None or time.monotonic() < deadline:
            if _one_exited(children):
                return 1
            time.sleep(0.2)
    except KeyboardInterrupt:
        print("[cell] stopping", flush=True)
    finally:
        status = max(status, _stop_all(children))
        signal.signal(signal.SIGTERM, previous)
    return status


def _stop_all(children: Children) -> int:
    """Interrupt every child still running and wait for all (killing those still running
    ``STOP_LIMIT_S`` later); 1 if one was killed or ended its stop with a status other than 0
    (each named), else 0. A child that had exited before the stop was reported then."""
    stopping = []
    for name, process in children:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            stopping.append((name, process))
    deadline = time.monotonic() + STOP_LIMIT_S
    status = 0
    for name, process in stopping:
        try:
            code = process.wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            print(f"[cell] {name} did not stop within {STOP_LIMIT_S:g} s: killed", flush=True)
            process.kill()
            process.wait()
            status = 1
            continue
        # -SIGINT: the interrupt ended a node still loading its modules (before its handler)
        if code not in (0, -signal.SIGINT):
            print(f"[cell] {name} ended its stop with exit status {code}", flush=True)
            status = 1
    return status


def run_composed(
    cell: CellDescription, parameters_file: Path, duration: float | None, extras: Extras = ()
) -> int:
    """The nodes in this process; ``extras`` (the live view) as child processes beside them."""
    children: Children = []
    status = 0
    try:
        # the imports take seconds (rclpy, the nodes' modules): a Ctrl-C meanwhile stops the
        # cell as it does once the nodes run (nothing started yet to stop), exit status 0
        import importlib

        from feeder_ros.nodes.catalog import NODE_MODULES
        from feeder_ros.ros_compat import RosSession

        modules = {name.rsplit(".", 1)[-1]: name for name in NODE_MODULES}
        classes = {
            executable: importlib.import_module(modules[executable]).NODE_CLASS
            for executable in {launch.executable for launch in cell.nodes}
        }
        for name, command in extras:
            _start(name, command, children)
        with RosSession() as init:
            if _spin_composed(cell, classes, init.context, parameters_file, duration, children):
                status = 1
    except KeyboardInterrupt:
        # also: rclpy's handler shuts the context down, then chains to Python's
        # (KeyboardInterrupt), which can land anywhere in the shutdown: the cell is stopping
        # either way
        pass
    finally:
        faulthandler.cancel_dump_traceback_later()  # armed for the nodes' teardown
        status = max(status, _stop_all(children))
    print("[cell] stopped", flush=True)
    return status


def _spin_composed(
    cell: CellDescription,
    classes: dict[str, Any],
    context: Context,
    parameters_file: Path,
    duration: float | None,
    children: Children,
) -> bool:
    """Spin the nodes until ``duration`` ends or a signal; True if a child process exited by
    itself. The executor is shut down after the stop (``StopOnShutdown``) has let rclpy's signal
    thread finish with its guard condition."""
    from rclpy.executors import SingleThreadedExecutor

    from feeder_ros.nodes import runner

    # one thread: rclpy's multi-threaded executor spent the one core the GIL allows on its own
    # bookkeeping (the demo cell ran at 0.3-0.7x real time); heavy work (a speed table rebuild)
    # runs in the nodes' worker threads, in solver code that releases the GIL
    executor = SingleThreadedExecutor()
    nodes = []
    try:
        with runner.StopOnShutdown(context):
            for launch in cell.nodes:
                print(f"[cell] composing {launch.fully_qualified_name}", flush=True)
                node = classes[launch.executable](cli_args=launch.ros_arguments(parameters_file))
                nodes.append(node)
                executor.add_node(node)
            deadline = None if duration is None else time.monotonic() + duration
            while deadline is None or time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
                if _one_exited(children):
                    return True
        return False
    finally:
        # wait for callbacks in flight and end the executor's worker threads (left running, they
        # are joined at interpreter exit, and one stuck in a callback kept the process alive)
        executor.shutdown(timeout_sec=5.0)
        # the nodes' and the context's teardown in the middleware is bounded as a node's is
        faulthandler.dump_traceback_later(runner.TEARDOWN_LIMIT_S, exit=True)
        for node in nodes:
            executor.remove_node(node)
            node.destroy_node()


def _list(cell: CellDescription, params_out: Path | None) -> None:
    """The nodes' command lines, on ``params_out`` (written) or on ``parameters.yaml`` (printed
    after them: save it under that name to run the commands)."""
    document = parameters_document(cell)
    target = params_out if params_out is not None else Path("parameters.yaml")
    if params_out is not None:
        with atomic_text(params_out) as stream:
            stream.write(document)
    for node in cell.nodes:
        print(shlex.join([str(node.executable), *node.ros_arguments(target)]))
    if params_out is None:
        print(f"# {target} (save this as {target} to run the commands above):")
        print(document, end="")


def run(args: argparse.Namespace) -> int:
    path = args.config if args.config is not None else default_cell_path()
    if args.duration is not None and not args.duration > 0.0:
        raise CommandError(f"--duration {args.duration!r} must be > 0")
    if args.params_out is not None and not args.list:
        raise CommandError("--params-out goes with --list")
    check_output_file(
        args.params_out,
        "--params-out",
        by_name="the printed commands read the parameters from it (without --params-out they are"
        " printed)",
    )
    try:
        cell = load_cell(path, node_executables())
    except CellError as error:
        raise CommandError(str(error)) from None
    if args.list:
        _list(cell, args.params_out)
        return 0
    with tempfile.TemporaryDirectory(prefix="feeder_cell_") as directory:
        parameters_file = Path(directory) / "parameters.yaml"
        parameters_file.write_text(parameters_document(cell), encoding="utf-8")
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        print(
            f"[cell] {cell.name}: {len(cell.nodes)} nodes in {len(cell.feeders)} feeder(s)",
            flush=True,  # from this line on, Ctrl-C is the cell's normal stop (exit status 0)
        )
        runner = run_composed if args.composed else run_processes
        return runner(cell, parameters_file, args.duration, _extras(args))


def _extras(args: argparse.Namespace) -> Extras:
    """The live view (``--foxglove``): ``feeder view`` of every topic, a process of its own."""
    if args.foxglove is None:
        return ()
    view = [sys.executable, "-m", "feeder_ros.cli.main", "view", "--port", str(args.foxglove)]
    return [("live view", view)]
