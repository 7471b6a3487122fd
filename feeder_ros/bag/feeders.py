"""Which feeder a recorded topic belongs to: feeders are told apart by namespace.

A feeder's nodes publish under its namespace (``feeder cell`` starts each feeder's nodes with
``__ns:=<namespace>``), on the relative names in :data:`FEEDER_TOPICS` (the nodes' declared
interfaces, ``feeder_ros/nodes/*``; a test keeps the two in step). ``feeder record`` with its
default namespace ``/`` records every feeder of a cell into one bag: ``/feeder_a/carrier/state``,
``/feeder_b/carrier/state``, ... A topic's namespace is its name before a known relative name
(:func:`feeder_namespace`). A topic of a feeder message type under another name (remapped) belongs
to the feeder whose namespace holds it (the longest), or to the one feeder when there is one; with
several feeders and no namespace holding it, it is left out (:func:`group_feeders`).

``/diagnostics`` is global: a status belongs to the feeder whose namespace holds the status name
(the nodes name their statuses after their fully qualified node name, ``/feeder_a/...``); a status
named otherwise belongs to every feeder (:func:`owner`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field

__all__ = [
    "CARRIER_STATE",
    "CARRIER_STATE_BATCH",
    "DIAGNOSTIC_ARRAY",
    "DRIVE_COMMAND",
    "FEEDER_TOPICS",
    "PART_EXIT",
    "PART_SENSOR_EVENT",
    "PART_STATE_ARRAY",
    "VEHICLE_ESTIMATE",
    "FeederGroups",
    "Router",
    "feeder_namespace",
    "group_feeders",
    "namespace_slug",
    "normalize_namespace",
    "owner",
]

DRIVE_COMMAND = "feeder_ros/msg/DriveCommand"
CARRIER_STATE = "feeder_ros/msg/CarrierState"
CARRIER_STATE_BATCH = "feeder_ros/msg/CarrierStateBatch"
VEHICLE_ESTIMATE = "feeder_ros/msg/VehicleEstimate"
PART_STATE_ARRAY = "feeder_ros/msg/PartStateArray"
PART_SENSOR_EVENT = "feeder_ros/msg/PartSensorEvent"
PART_EXIT = "feeder_ros/msg/PartExit"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"

#: a feeder's topics relative to its namespace, with their types (what its nodes publish)
FEEDER_TOPICS: Mapping[str, str] = {
    "drive/command": DRIVE_COMMAND,
    "drive/state": "feeder_ros/msg/DriveState",
    "heartbeat": "std_msgs/msg/Header",
    "estimate": VEHICLE_ESTIMATE,
    "calibration": "feeder_ros/msg/PartCalibration",
    "imu": "sensor_msgs/msg/Imu",
    "imu/batch": "feeder_ros/msg/AccelerometerBatch",
    "carrier/state": CARRIER_STATE,
    "carrier/state_batch": CARRIER_STATE_BATCH,
    "parts/state": PART_STATE_ARRAY,
    "parts/sensor_events": PART_SENSOR_EVENT,
    "parts/exit": PART_EXIT,
    "speed/status": "feeder_ros/msg/SpeedStatus",
}
# longest first: "imu/batch" before "imu" would not matter ("/x/imu/batch" does not end in
# "/imu"), but a namespace ending in a relative name must not be cut short
_BY_LENGTH = sorted(FEEDER_TOPICS, key=len, reverse=True)


def normalize_namespace(namespace: str) -> str:
    """``feeder_a`` / ``/feeder_a/`` -> ``/feeder_a``; ``""`` and ``/`` -> ``/``."""
    stripped = namespace.strip().strip("/")
    return "/" + stripped


def namespace_slug(namespace: str) -> str:
    """A namespace as a file-name part: ``/cell/feeder_a`` -> ``cell_feeder_a`` (``/``: root)."""
    return normalize_namespace(namespace).strip("/").replace("/", "_") or "root"


def _under(topic: str, namespace: str) -> bool:
    return namespace == "/" or topic.startswith(namespace + "/")


def feeder_namespace(topic: str, type_name: str | None = None) -> str | None:
    """The namespace of a topic named like a feeder's (``/a/b/carrier/state`` -> ``/a/b``), None
    for another name or (``type_name`` given) another type than the feeder's topic has."""
    for relative in _BY_LENGTH:
        if topic == "/" + relative or topic.endswith("/" + relative):
            if type_name is not None and FEEDER_TOPICS[relative] != type_name:
                continue
            return topic[: len(topic) - len(relative) - 1] or "/"
    return None


def owner(name: str, namespaces: Collection[str]) -> str | None:
    """The namespace among ``namespaces`` that holds ``name`` (a topic, or a diagnostic status
    named after its node: ``/feeder_a/drive_interface: drive``), the longest; None: none does."""
    holders = [ns for ns in namespaces if _under(name, ns)]
    return max(holders, key=len) if holders else None


def _parent(topic: str) -> str:
    return topic.rsplit("/", 1)[0] or "/"


@dataclass(frozen=True)
class FeederGroups:
    """Topics of feeder types by feeder: ``routes`` maps topic -> namespace; ``unassigned`` are
    topics no feeder can be told for (several feeders, no namespace holding them)."""

    routes: dict[str, str] = field(default_factory=dict)
    unassigned: tuple[str, ...] = ()

    @property
    def namespaces(self) -> list[str]:
        return sorted(set(self.routes.values()))


def group_feeders(topics: Mapping[str, str]) -> FeederGroups:
    """Group the topics (``name -> type``) of feeder message types by feeder namespace (see the
    module docstring). A bag with one feeder gives one group (every feeder topic in it)."""
    routes: dict[str, str] = {}
    others: list[str] = []
    for topic, type_name in topics.items():
        namespace = feeder_namespace(topic, type_name)
        if namespace is None:
            others.append(topic)
        else:
            routes[topic] = namespace
    namespaces = set(routes.values())
    unassigned: list[str] = []
    if not namespaces and others:  # no name tells: one feeder, in the namespace all share
        parts = [_parent(t).split("/") for t in others]
        common: list[str] = []
        for level in zip(*parts, strict=False):
            if len(set(level)) > 1:
                break
            common.append(level[0])
        shared = "/".join(common) or "/"
        return FeederGroups(dict.fromkeys(others, shared))
    for topic in others:
        holder = owner(topic, namespaces) if len(namespaces) > 1 else next(iter(namespaces))
        if holder is None:
            unassigned.append(topic)
        else:
            routes[topic] = holder
    return FeederGroups(routes, tuple(sorted(unassigned)))


class Router:
    """Which feeder a topic's batches go to while a bag is read, before all its topics are known:
    by name (:func:`feeder_namespace`), else the topic's parent namespace. ``fixed``: the groups
    of a previous pass over the bag (used as they are). After the pass, ``routes`` holds what was
    used: when it differs from :func:`group_feeders` of all the topics, the bag is read again with
    those groups fixed."""

    def __init__(self, fixed: FeederGroups | None = None) -> None:
        self.fixed = fixed
        self.routes: dict[str, str | None] = {}
        self.types: dict[str, str] = {}

    def __call__(self, topic: str, type_name: str) -> str | None:
        if topic in self.routes:
            return self.routes[topic]
        self.types[topic] = type_name
        if self.fixed is not None:
            namespace = self.fixed.routes.get(topic)
        else:
            namespace = feeder_namespace(topic, type_name) or _parent(topic)
        self.routes[topic] = namespace
        return namespace

    def settled(self) -> FeederGroups | None:
        """None if the routes used are those of all the topics seen; else the groups to use."""
        groups = group_feeders(self.types)
        used = {t: ns for t, ns in self.routes.items() if ns is not None}
        return None if used == groups.routes else groups
