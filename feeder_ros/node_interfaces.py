"""What each node offers on the ROS graph, as data: topics, services and parameters.

Each node module declares one :class:`NodeInterface`; the README's interface tables are generated
from these declarations (``python -m feeder_ros.docgen``) and tests check the running nodes against
them, so the documentation cannot drift from the code. ROS-free on purpose.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from feeder_ros.physics.parameters import ParameterSpec

__all__ = ["NodeInterface", "ServiceSpec", "TopicSpec"]


@dataclass(frozen=True)
class TopicSpec:
    name: str  # relative unless it must be global (e.g. /diagnostics, /clock)
    type: str  # ROS type name, e.g. "feeder_ros/msg/DriveCommand"
    qos: str  # short description, e.g. "reliable, depth 10" or "sensor data (best effort, depth 5)"
    description: str


@dataclass(frozen=True)
class ServiceSpec:
    name: str
    type: str
    description: str


@dataclass(frozen=True)
class NodeInterface:
    executable: str
    node_name: str
    summary: str
    publishes: tuple[TopicSpec, ...] = ()
    subscribes: tuple[TopicSpec, ...] = ()
    services: tuple[ServiceSpec, ...] = ()
    parameters: Mapping[str, ParameterSpec] = field(default_factory=dict)
