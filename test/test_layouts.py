"""The shipped Foxglove and PlotJuggler layouts (config/*_layout.*) name only what the demo cell
publishes: every topic is one a node of config/cell.yaml declares, every field path exists in that
topic's message type (arrays indexed, nested messages followed), every panel is placed once."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path
from typing import Any

import pytest

from feeder_ros.cell import load_cell
from feeder_ros.cli.cell import node_executables
from feeder_ros.nodes.catalog import node_interfaces
from feeder_ros.recording import message_class

CONFIG = Path(__file__).resolve().parents[1] / "config"
INDEX = re.compile(r"^(\w+)(\[(\d+|:)\])?$")


def cell_topics() -> dict[str, str]:
    """Topic -> type of everything the demo cell's nodes publish."""
    interfaces = {i.executable: i for i in node_interfaces()}
    topics = {}
    for node in load_cell(CONFIG / "cell.yaml", node_executables()).nodes:
        for spec in interfaces[node.executable].publishes:
            if spec.name.startswith("~"):
                continue
            name = spec.name if spec.name.startswith("/") else f"{node.namespace}/{spec.name}"
            topics[name] = spec.type
    return topics


def check_field(type_name: str, fields: list[str], where: str) -> None:
    """Raise AssertionError unless ``fields`` (each ``name`` or ``name[i]``/``name[:]``) is a
    path into ``type_name`` ending on a number."""
    cls = message_class(type_name)
    for position, field in enumerate(fields):
        match = INDEX.match(field)
        assert match, f"{where}: {field!r} is not a field"
        kinds = cls.get_fields_and_field_types()
        assert match.group(1) in kinds, f"{where}: {type_name} has no field {match.group(1)}"
        kind = kinds[match.group(1)]
        array = kind.startswith("sequence<") or kind.endswith("]")
        assert array == (match.group(2) is not None), f"{where}: {field} indexes {kind} wrongly"
        base = re.sub(r"^sequence<(.*)>$", r"\1", re.sub(r"\[\d*\]$", "", kind))
        if "/" in base:
            assert position < len(fields) - 1, f"{where}: {field} is a {base}, not a number"
            cls = message_class(base.replace("/", "/msg/", 1) if "/msg/" not in base else base)
            type_name = base
            continue
        assert position == len(fields) - 1, f"{where}: {field} is a {base}, not a message"
        assert base in {"double", "float", "int8", "uint8", "int16", "uint16", "int32", "uint32",
                        "int64", "uint64", "boolean"}, f"{where}: {field} is a {base}"  # fmt: skip


def split_topic(path: str, topics: dict[str, str], separator: str) -> tuple[str, list[str]]:
    """The longest published topic that ``path`` starts with, and the field names after it."""
    for topic in sorted(topics, key=len, reverse=True):
        if path.startswith(topic + separator):
            return topic, path[len(topic) + 1 :].split(separator)
    raise AssertionError(f"{path}: no topic the demo cell publishes")


def check_path(path: str, topics: dict[str, str], separator: str) -> None:
    topic, fields = split_topic(path, topics, separator)
    check_field(topics[topic], fields, path)


def panel_ids(node: Any) -> list[str]:
    if isinstance(node, str):
        return [node]
    return panel_ids(node["first"]) + panel_ids(node["second"])


def test_the_foxglove_layout_names_what_the_cell_publishes() -> None:
    topics = cell_topics()
    layout = json.loads((CONFIG / "foxglove_layout.json").read_text())
    placed = panel_ids(layout["layout"])
    assert sorted(placed) == sorted(layout["configById"])  # each panel placed once
    plotted = []
    for panel, config in layout["configById"].items():
        for path in config.get("paths", []):
            check_path(path["value"], topics, ".")
            plotted.append(split_topic(path["value"], topics, ".")[0])
        if "topicPath" in config:
            assert config["topicPath"] in topics, panel
        if "topicToRender" in config:
            assert topics[config["topicToRender"]] == "diagnostic_msgs/msg/DiagnosticArray"
    assert {"/demo_cell/feeder_1/speed/status", "/demo_cell/feeder_1/drive/state"} <= set(plotted)


def test_the_plotjuggler_layout_names_what_the_cell_publishes() -> None:
    topics = cell_topics()
    root = ElementTree.parse(CONFIG / "plotjuggler_layout.xml").getroot()
    snippets = {s.get("name"): s for s in root.iter("snippet")}
    sources = [e.text or "" for s in snippets.values() for e in s.iter()
               if e.tag == "linked_source" or e.tag.startswith("v")]  # fmt: skip
    curves = [c.get("name") or "" for c in root.iter("curve")]
    assert len(curves) == 9
    for name in [c for c in curves if c not in snippets] + sources:
        check_path(name, topics, "/")
    assert set(snippets) <= set(curves)  # every derived series is drawn


@pytest.mark.parametrize(
    ("path", "message"),
    [
        ("/demo_cell/feeder_1/speed/status.speed", "has no field speed"),
        ("/demo_cell/feeder_1/imu/batch.acceleration_x_mps2", "indexes sequence<double> wrongly"),
        ("/demo_cell/feeder_1/nothing.x", "no topic the demo cell publishes"),
        ("/demo_cell/feeder_1/drive/state.header", "is a std_msgs/Header, not a number"),
        ("/demo_cell/feeder_1/drive/state.header.frame_id", "is a string"),
    ],
)
def test_the_check_refuses_what_foxglove_could_not_plot(path: str, message: str) -> None:
    topics = cell_topics()
    with pytest.raises(AssertionError, match=re.escape(message)):
        check_path(path, topics, ".")
