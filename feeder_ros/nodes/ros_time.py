"""ROS time as float seconds, one way for every node.

Stamps and clocks carry integer seconds and nanoseconds; the cores (drive, estimation,
monitoring) work in float seconds, which hold today's epoch (1.8e9 s) to about 0.2 us.
"""

from __future__ import annotations

from typing import Any

__all__ = ["clock_seconds", "stamp_seconds"]


def stamp_seconds(stamp: Any) -> float:
    """A ``builtin_interfaces/Time`` (a header's stamp) in seconds."""
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def clock_seconds(clock: Any) -> float:
    """The time of an ``rclpy`` clock (a node's ROS clock: sim time under ``use_sim_time``) now,
    in seconds."""
    return float(clock.now().nanoseconds) * 1e-9
