"""Helpers for tests that start real ROS 2 processes and watch the graph over DDS."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import threading
import time
import weakref
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import rclpy
from lifecycle_msgs.srv import GetState
from rcl_interfaces.srv import (
    DescribeParameters,
    GetParameters,
    GetParameterTypes,
    ListParameters,
    SetParameters,
    SetParametersAtomically,
)
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from feeder_ros.nodes.service_calls import ServiceCallError, call_service

REPO = Path(__file__).resolve().parents[1]


def console_scripts() -> dict[str, str]:
    """setup.py's console_scripts as {executable: "module:function"} (the installed executables)."""
    tree = ast.parse((REPO / "setup.py").read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "CONSOLE_SCRIPTS" for t in node.targets
        ):
            entries = ast.literal_eval(node.value)
            return dict(tuple(part.strip() for part in entry.split("=")) for entry in entries)
    raise AssertionError("setup.py has no CONSOLE_SCRIPTS list")


def node_executables() -> list[str]:
    """Executables whose entry point is a node (a module under feeder_ros.nodes)."""
    return sorted(
        exe for exe, target in console_scripts().items() if target.startswith("feeder_ros.nodes.")
    )


def sourced_environment(setup_script: Path) -> dict[str, str]:
    """The environment after `source setup_script` in bash (what a ROS user's shell has)."""
    output = subprocess.run(
        ["bash", "-c", f"source '{setup_script}' && env -0"],
        check=True,
        capture_output=True,
        env=dict(os.environ),
    ).stdout
    pairs = (item.split("=", 1) for item in output.decode().split("\0") if "=" in item)
    return dict(pairs)


def wait_until(predicate: Callable[[], bool], timeout_s: float) -> bool:
    """Poll ``predicate`` (callbacks run in the probe's spinning thread) until true or timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


@contextmanager
def probe_node(name: str = "feeder_test_probe") -> Iterator[Node]:
    """An rclpy node in its own context, spun by a background thread (subscriptions fill lists
    while the test thread waits or makes service calls with :func:`call`). Should the spinning
    thread die of an error, the probe's exit says so (instead of topics that just go quiet).

    An error once the probe is shutting down is not the test's: rclpy 9.1's executor can trip over
    its own shutdown (``shutdown()`` destroys its guard condition while ``spin_once`` makes a
    handler with it, which then calls ``trigger()`` on None); such an error is only printed."""
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    errors: list[BaseException] = []
    stopping = threading.Event()

    def spin() -> None:
        try:
            executor.spin()
        except BaseException as error:  # reported at the probe's exit
            if stopping.is_set():
                print(f"the probe's executor thread failed while shutting down: {error!r}")
            else:
                errors.append(error)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield node
    finally:
        stopping.set()
        executor.shutdown()
        thread.join(timeout=5)
        _clients.pop(node, None)
        node.destroy_node()
        rclpy.shutdown(context=context)
        if errors:  # (shown with a failure the dead thread caused, e.g. a wait that timed out)
            print(f"the probe's executor thread died: {errors[0]!r}")
    if errors:
        raise AssertionError(f"the probe's executor thread died: {errors[0]!r}") from errors[0]


#: one client per probe, service type and name, kept for the probe's life: destroying a client
#: while the probe's executor thread spins can raise InvalidHandle in that thread (rclpy checks
#: ``client.handle`` of the node's live client list after each wait) and stop it
_clients: weakref.WeakKeyDictionary[Node, dict[tuple[Any, str], Any]] = weakref.WeakKeyDictionary()


#: services whose request can be sent again with the same outcome: reads, and parameter sets
#: (the same values set twice leave the node as once). :func:`call` repeats them when no answer
#: comes within its attempt window.
REPEATABLE_SERVICES: tuple[Any, ...] = (
    DescribeParameters,
    GetParameters,
    GetParameterTypes,
    ListParameters,
    SetParameters,
    SetParametersAtomically,
    GetState,
)


def call(
    node: Node,
    service_type: Any,
    name: str,
    request: Any,
    timeout_s: float = 30.0,
    attempt_s: float = 5.0,
    repeatable: bool | None = None,
) -> Any:
    """Call a service from the test thread (the probe's executor thread delivers the answer).

    A reply can be lost in DDS discovery: ``wait_for_service`` sees the server, but the server may
    not yet have matched the client's fresh reply reader when the request arrives; Fast DDS then
    drops the reply ("failed to send response (timeout)" in the server's log). So a request of
    :data:`REPEATABLE_SERVICES` is sent again when ``attempt_s`` pass without an answer (until
    ``timeout_s``; :func:`feeder_ros.nodes.service_calls.call_service`). Other requests are sent
    once: sent twice, they could act twice; ``repeatable=True`` marks one that cannot (a request
    the server refuses, the first call of a new client being the exposed one). (Waiting after a
    new client is seen would not be safe either: tests time what a call sets off from just
    before it.)"""
    clients = _clients.setdefault(node, {})
    client = clients.get((service_type, name))
    if client is None:
        client = clients[(service_type, name)] = node.create_client(service_type, name)
    assert client.wait_for_service(timeout_sec=timeout_s), f"{name} not available"
    if repeatable is None:
        repeatable = service_type in REPEATABLE_SERVICES
    ask_again_s = attempt_s if repeatable else None
    try:
        return call_service(client, request, timeout_s, ask_again_s)
    except ServiceCallError as error:
        raise AssertionError(
            f"{name} did not answer within {timeout_s} s (an answer lost in DDS discovery shows"
            " as 'failed to send response' in the server's output)"
        ) from error


class DrainedProcess(subprocess.Popen[str]):
    """A child process whose stdout and stderr are read continuously into memory by a thread.

    A node's output must never sit in an unread pipe: once a pipe's 64 KiB buffer is full, the
    node blocks in its next log call and stops publishing (a stalled clock, a silent topic).
    :meth:`output` returns everything printed so far."""

    def __init__(self, command: Sequence[str], **kwargs: Any) -> None:
        super().__init__(
            list(command), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kwargs
        )
        self._lines: list[str] = []
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()

    def _drain(self) -> None:
        assert self.stdout is not None
        for line in self.stdout:
            self._lines.append(line)

    def output(self) -> str:
        """Everything the process printed so far (all of it once it has exited)."""
        if self.poll() is not None:
            self._reader.join(timeout=5)
        return "".join(self._lines)


@contextmanager
def running(
    command: Sequence[str], env: dict[str, str] | None = None, **kwargs: Any
) -> Iterator[DrainedProcess]:
    """Start a process; on exit interrupt it (Ctrl-C) and insist it ended cleanly. If the test
    failed or the process ended with a status other than 0, the end of its output is printed
    (pytest shows it with the failure: tests assert the status after the block)."""
    process = DrainedProcess(command, env=env, **kwargs)
    failed = True
    try:
        yield process
        failed = False
    finally:
        stuck = False
        if process.poll() is None:
            process.send_signal(2)  # SIGINT, as Ctrl-C
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
                stuck = True
        if failed or stuck or process.returncode != 0:
            tail = process.output()[-4000:]
            print(f"--- output of {Path(command[0]).name} (exit {process.returncode}):\n{tail}")
        if stuck:
            raise AssertionError(f"{command[0]} did not stop on Ctrl-C within 10 s")


def python_command(*args: str) -> list[str]:
    return [sys.executable, *args]


def demo_cell_file(
    tmp_path: Path,
    namespace: str,
    *,
    without: Sequence[str] = (),
    parameters: dict[str, dict[str, Any]] | None = None,
    name: str | None = None,
) -> Path:
    """config/cell.yaml's feeder under ``namespace``, its parameter files named by absolute path,
    the nodes in ``without`` left out and ``parameters`` (node -> parameters) merged over the
    cell's (a nested dict replaces the cell's whole entry); written to ``tmp_path``."""
    import yaml  # (only the cell tests need it)

    config = REPO / "config"
    tree = yaml.safe_load((config / "cell.yaml").read_text(encoding="utf-8"))
    if name is not None:
        tree["cell"]["name"] = name
    [feeder] = tree["cell"]["feeders"]
    feeder["namespace"] = namespace
    nodes = feeder["nodes"]
    for node in without:
        del nodes[node]
    for spec in nodes.values():
        if "params_file" in spec:
            spec["params_file"] = str(config / spec["params_file"])
    for node, values in (parameters or {}).items():
        nodes[node].setdefault("parameters", {}).update(values)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(tree), encoding="utf-8")
    return path
