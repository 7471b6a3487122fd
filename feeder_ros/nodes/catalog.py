"""The node modules this package installs as executables (kept equal to setup.py by a test)."""

from __future__ import annotations

import importlib

from feeder_ros.node_interfaces import NodeInterface

NODE_MODULES: tuple[str, ...] = (
    "feeder_ros.nodes.drive_interface",
    "feeder_ros.nodes.manual_drive",
    "feeder_ros.nodes.platform_simulator",
    "feeder_ros.nodes.vehicle_estimator",
    "feeder_ros.nodes.speed_monitor",
)


def node_interfaces() -> list[NodeInterface]:
    """Each node module's declared interface, importing the modules (needs rclpy)."""
    return [importlib.import_module(name).INTERFACE for name in NODE_MODULES]
