"""ROS 2 launch file for a feeder cell, reading the same description as ``feeder cell``.

    ros2 launch feeder_ros feeder_cell.launch.py cell:=/path/to/cell.yaml

Without ``cell:=``, the installed ``config/cell.yaml`` is used. Each node of each feeder becomes a
``launch_ros`` Node in its namespace, with the parameters the description gives it.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from feeder_ros.cell import load_cell, parameters_document


def _nodes(context, *args, **kwargs):  # type: ignore[no-untyped-def]
    cell = load_cell(Path(LaunchConfiguration("cell").perform(context)))
    parameters = Path(tempfile.mkdtemp(prefix="feeder_cell_")) / "parameters.yaml"
    parameters.write_text(parameters_document(cell), encoding="utf-8")
    return [
        Node(
            package="feeder_ros",
            executable=launch.executable,
            name=launch.node_name,
            namespace=launch.namespace,
            parameters=[str(parameters)],
            output="screen",
        )
        for launch in cell.nodes
    ]


def generate_launch_description() -> LaunchDescription:
    default = Path(get_package_share_directory("feeder_ros")) / "config" / "cell.yaml"
    return LaunchDescription(
        [
            DeclareLaunchArgument("cell", default_value=str(default)),
            OpaqueFunction(function=_nodes),
        ]
    )
