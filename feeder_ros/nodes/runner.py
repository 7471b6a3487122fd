"""``main()`` plumbing shared by every node: init, spin, clean shutdown on Ctrl-C or SIGTERM."""

from __future__ import annotations

import faulthandler
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from feeder_ros.physics.parameters import ParameterError
from feeder_ros.ros_compat import RosSession

#: seconds a node's teardown (node destroyed, context shut down) may take once its spin has
#: stopped; past that the process ends with status 1 and every thread's stack on stderr. The DDS
#: teardown can hang: a node stopped by SIGTERM when its cell supervisor was killed once spun for
#: good in Fast DDS's ``DomainParticipant::set_listener`` (``rmw_destroy_node`` ->
#: ``destroy_participant``), an orphan burning a core; on Kilted a speed monitor stopped by its
#: cell hung there for 10 s. faulthandler's watchdog is a C thread, so it fires even while that
#: C call holds the GIL. A whole cell's teardown takes 1.4-2.5 s (two busy processes beside it);
#: 5 s is ROS launch's default wait between SIGINT and SIGTERM. ``feeder cell`` waits longer
#: (``cli.cell.STOP_LIMIT_S``), so such a node ends by this limit, its stacks printed.
TEARDOWN_LIMIT_S = 5.0


class StopOnShutdown:
    """``with StopOnShutdown(context):`` around a spin loop.

    Ctrl-C, SIGTERM (rclpy turns both into a context shutdown, then a ``KeyboardInterrupt`` or
    ``ExternalShutdownException``) and the ``RuntimeError`` rclpy raises when it takes a message
    that arrived while the context was shutting down are the stop that was asked for: they end
    the block quietly and set ``stopped``. Every other error propagates.

    rclpy shuts the context down from its own signal thread, so a take can fail on the signal
    (``RuntimeError: Unable to convert call argument '0' to Python object``, seen when a cell
    stopped its nodes) a moment before ``context.ok()`` turns false: a ``RuntimeError`` is a stop
    if the context goes down within ``shutdown_wait_s``.

    A Ctrl-C also waits (as long) for that thread before the block ends: Python raises the
    ``KeyboardInterrupt`` as soon as the main thread runs, and rclpy's signal thread (Jazzy 7.1,
    Kilted 9.1) may not have run yet. That thread triggers every executor's SIGINT guard
    condition and then shuts the contexts down; an executor shut down in between frees a guard
    condition it is about to trigger. CI saw a composed cell hang in
    ``uninstall_signal_handlers``; with the thread starved (SCHED_IDLE beside three busy
    processes) a composed cell crashed (SIGSEGV) in 2 of 18 stops. Once the context is down the
    thread has done both.
    """

    #: how long a RuntimeError waits for the context's shutdown to show [s]
    shutdown_wait_s = 1.0

    def __init__(self, context: Context) -> None:
        self.context = context
        self.stopped = False

    def _shutting_down(self) -> bool:
        deadline = time.monotonic() + self.shutdown_wait_s
        while self.context.ok():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    def __enter__(self) -> StopOnShutdown:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: Any
    ) -> bool:
        if kind is None:
            return False
        if issubclass(kind, KeyboardInterrupt):
            self._shutting_down()  # rclpy's signal thread first (see above)
        requested = issubclass(kind, KeyboardInterrupt | ExternalShutdownException) or (
            issubclass(kind, RuntimeError) and self._shutting_down()
        )
        self.stopped = requested
        return requested


def run_node(make_node: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Create the node inside an rclpy context and spin it until shutdown; returns an exit code.

    rclpy's signal handlers turn SIGINT (Ctrl-C) and SIGTERM into a context shutdown, so a cell
    supervisor stopping the node gets the same orderly exit: node destroyed, context shut down,
    exit status 0. A teardown that takes longer than :data:`TEARDOWN_LIMIT_S` ends the process
    with status 1 (stacks on stderr). Bad ROS arguments (an unreadable or malformed params file)
    and parameter values the node refuses end it with status 2 and the reason logged. A stop
    while the node is being built ends it with status 0 too.
    """
    argv = list(sys.argv if args is None else args)
    try:
        initialized = RosSession(args=argv)
    except RCLError as error:
        # the ROS arguments themselves are bad (an unreadable or malformed --params-file, a bad
        # remapping): rcl names what it could not use
        rclpy.logging.get_logger("feeder_ros").error(f"refusing to start: {error}")
        return 2
    try:
        with initialized:
            try:
                node = make_node()
            except Exception as error:
                if not initialized.context.ok():
                    # stopped (SIGINT, SIGTERM) while the node was built: rclpy shut the context
                    # down under it, whatever failed next ("context is not valid") is that stop
                    return 0
                if isinstance(error, ParameterError | ParameterException | ValueError):
                    rclpy.logging.get_logger("feeder_ros").error(f"refusing to start: {error}")
                    return 2
                raise
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            try:
                with StopOnShutdown(node.context):
                    executor.spin()
            finally:
                faulthandler.dump_traceback_later(TEARDOWN_LIMIT_S, exit=True)
                executor.remove_node(node)
                node.destroy_node()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        faulthandler.cancel_dump_traceback_later()
    return 0
