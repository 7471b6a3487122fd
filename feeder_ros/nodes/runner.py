"""``main()`` plumbing shared by every node: init, spin, clean shutdown on Ctrl-C or SIGTERM."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from feeder_ros.physics.parameters import ParameterError


def run_node(make_node: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Create the node inside an rclpy context and spin it until shutdown; returns an exit code.

    rclpy's signal handlers turn SIGINT (Ctrl-C) and SIGTERM into a context shutdown, so a cell
    supervisor stopping the node gets the same orderly exit: node destroyed, context shut down,
    exit status 0.
    """
    argv = list(sys.argv if args is None else args)
    try:
        with rclpy.init(args=argv):
            try:
                node = make_node()
            except (ParameterError, ParameterException, ValueError) as error:
                rclpy.logging.get_logger("feeder_ros").error(f"refusing to start: {error}")
                return 2
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            try:
                executor.spin()
            except RuntimeError:
                # rclpy can fail to take a message that arrived while Ctrl-C shut the context
                # down; that is the shutdown we asked for, anything else is a real error.
                if node.context.ok():
                    raise
            finally:
                executor.remove_node(node)
                node.destroy_node()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    return 0
