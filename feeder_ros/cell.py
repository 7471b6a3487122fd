"""Cell descriptions: which feeders, in which namespaces, running which nodes with which parameters.

One YAML file (``config/cell.yaml``) describes a cell; ``feeder cell`` starts it as processes (like
a launch file) or composed in one process, and ``launch/feeder_cell.launch.py`` reads the same file
for ROS installations. This module is ROS-free: it parses and checks the description and turns it
into command lines and a ``ros__parameters`` file.

Format::

    cell:
      name: demo_cell
      use_sim_time: false
      feeders:
        - namespace: /demo_cell/feeder_1
          nodes:
            platform_simulator:
              params_file: platform_simulator.yaml   # relative to the cell file
              section: platform_simulator_realistic  # which node section of it to use
              parameters: {feed_interval_s: 3.0}
            vehicle_estimator: {}
            drive_interface: {parameters: {backend: sim}}
            speed_monitor: {}
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from feeder_ros.yaml_files import YamlFileError, read_yaml

__all__ = [
    "CellDescription",
    "CellError",
    "FeederDescription",
    "NodeLaunch",
    "load_cell",
    "parameters_document",
]

_NAMESPACE = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")
_SCALAR = (bool, int, float, str)


class CellError(ValueError):
    """A cell description that cannot be run; the message names the file and the entry."""


@dataclass(frozen=True)
class NodeLaunch:
    executable: str
    namespace: str
    parameters: Mapping[str, Any] = field(default_factory=dict)

    @property
    def node_name(self) -> str:
        return self.executable

    @property
    def fully_qualified_name(self) -> str:
        return f"{self.namespace}/{self.node_name}"

    def ros_arguments(self, parameters_file: Path) -> list[str]:
        """``--ros-args`` for the node: its namespace and the cell's parameter file."""
        return [
            "--ros-args",
            "-r", f"__ns:={self.namespace}",
            "-r", f"__node:={self.node_name}",
            "--params-file", str(parameters_file),
        ]  # fmt: skip


@dataclass(frozen=True)
class FeederDescription:
    namespace: str
    nodes: tuple[NodeLaunch, ...]


@dataclass(frozen=True)
class CellDescription:
    name: str
    use_sim_time: bool
    feeders: tuple[FeederDescription, ...]
    source: Path

    @property
    def nodes(self) -> list[NodeLaunch]:
        return [node for feeder in self.feeders for node in feeder.nodes]


def _mapping(value: object, where: str) -> Mapping[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise CellError(f"{where}: expected a mapping, got {value!r}")
    return value


def _flatten(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested parameter groups (``plant: {damping_ns_per_m: 200}``) as dotted names, the form
    ROS gives them (``plant.damping_ns_per_m``), so that a cell override replaces the value."""
    flat: dict[str, Any] = {}
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


def _section(path: Path, name: str, where: str) -> dict[str, Any]:
    """The ros__parameters of node section ``name`` of a ROS parameter file, flattened."""
    try:
        document = read_yaml(path)
    except OSError as error:
        raise CellError(f"{where}: cannot read params_file {path}: {error.strerror}") from None
    except YamlFileError as error:
        raise CellError(f"{where}: params_file {error}") from None
    for key in (name, f"/{name}", f"/**/{name}"):
        if isinstance(document, Mapping) and key in document:
            section = document[key]
            if isinstance(section, Mapping) and isinstance(section.get("ros__parameters"), Mapping):
                return _flatten(section["ros__parameters"])
    raise CellError(f"{where}: {path} has no section '{name}: ros__parameters: ...'")


def load_cell(path: Path, known_executables: frozenset[str] | None = None) -> CellDescription:
    """Parse and check a cell description; ``known_executables`` limits the node names."""
    try:
        document = read_yaml(path)
    except OSError as error:
        raise CellError(f"cannot read cell description {path}: {error.strerror}") from None
    except YamlFileError as error:
        raise CellError(str(error)) from None
    cell = _mapping(_mapping(document, str(path)).get("cell"), f"{path}: cell")
    name = cell.get("name", path.stem)
    use_sim_time = cell.get("use_sim_time", False)
    if not isinstance(use_sim_time, bool):
        raise CellError(f"{path}: cell.use_sim_time={use_sim_time!r} is not true or false")
    feeders_raw = cell.get("feeders")
    if not isinstance(feeders_raw, list) or not feeders_raw:
        raise CellError(f"{path}: cell.feeders must be a non-empty list")
    feeders: list[FeederDescription] = []
    seen: set[str] = set()
    for index, entry in enumerate(feeders_raw):
        where = f"{path}: cell.feeders[{index}]"
        entry = _mapping(entry, where)
        namespace = entry.get("namespace")
        if not isinstance(namespace, str) or not _NAMESPACE.match(namespace):
            raise CellError(f"{where}: namespace={namespace!r} is not an absolute ROS namespace")
        if namespace in seen:
            raise CellError(f"{where}: namespace {namespace} is used twice")
        seen.add(namespace)
        nodes_raw = _mapping(entry.get("nodes"), f"{where}.nodes")
        if not nodes_raw:
            raise CellError(f"{where}: no nodes")
        nodes = []
        for executable, spec in nodes_raw.items():
            node_where = f"{where}.nodes.{executable}"
            if known_executables is not None and executable not in known_executables:
                raise CellError(
                    f"{node_where}: unknown node; known: {', '.join(sorted(known_executables))}"
                )
            spec = _mapping(spec, node_where)
            unknown = set(spec) - {"params_file", "section", "parameters"}
            if unknown:
                raise CellError(f"{node_where}: unknown key(s) {', '.join(sorted(unknown))}")
            values: dict[str, Any] = {}
            if "params_file" in spec:
                values.update(
                    _section(
                        path.parent / str(spec["params_file"]),
                        str(spec.get("section", executable)),
                        node_where,
                    )
                )
            overrides = _flatten(_mapping(spec.get("parameters"), f"{node_where}.parameters"))
            for key, value in overrides.items():
                if not isinstance(value, _SCALAR) and not (
                    isinstance(value, list) and all(isinstance(v, _SCALAR) for v in value)
                ):
                    raise CellError(f"{node_where}.parameters.{key}={value!r} is not a value")
                values[str(key)] = value
            if use_sim_time:
                values["use_sim_time"] = True
            nodes.append(NodeLaunch(str(executable), namespace, values))
        feeders.append(FeederDescription(namespace, tuple(nodes)))
    return CellDescription(str(name), use_sim_time, tuple(feeders), path)


def parameters_document(cell: CellDescription) -> str:
    """A ``ros__parameters`` YAML file with every node's values, keyed by fully qualified name."""
    document = {
        node.fully_qualified_name: {"ros__parameters": dict(node.parameters)} for node in cell.nodes
    }
    return yaml.safe_dump(document, sort_keys=False)
