"""The estimator's and the speed monitor's parameter files in config/: every parameter at its
default, and loaded by the node (rcl's YAML parser) in any namespace."""

from __future__ import annotations

import importlib
import math
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from ros_test_tools import call, probe_node, running

BIN = Path(sys.executable).parent
CONFIG = Path(__file__).resolve().parents[2] / "config"
NODES = ("vehicle_estimator", "speed_monitor")


def _same(a: Any, b: Any) -> bool:
    both_nan = isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    return both_nan or (type(a) is type(b) and a == b)


def _file_values(node: str, path: Path | None = None) -> dict[str, Any]:
    tree = yaml.safe_load((path or CONFIG / f"{node}.yaml").read_text(encoding="utf-8"))
    assert list(tree) == [f"/**/{node}"]
    return _flat(tree[f"/**/{node}"]["ros__parameters"])


def _flat(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested keys joined with dots, as rcl reads them (calibration.file, say)."""
    values: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            values.update(_flat(value, f"{prefix}{key}."))
        else:
            values[f"{prefix}{key}"] = value
    return values


@pytest.mark.parametrize("node", NODES)
def test_config_file_lists_every_parameter_at_its_default(node: str) -> None:
    module = importlib.import_module(f"feeder_ros.nodes.{node}")
    values = _file_values(node)
    assert sorted(values) == sorted(module.PARAMETERS)
    for name, value in values.items():
        spec = module.PARAMETERS[name]
        # the file's YAML type is the parameter's (1.0 for a double: the file documents the type)
        assert _same(spec.check(value), module.DEFAULTS[name]), name
        assert type(value) is spec.kind, (name, value)


def _value(message: Any) -> Any:
    if message.type == ParameterType.PARAMETER_DOUBLE:
        return message.double_value
    if message.type == ParameterType.PARAMETER_INTEGER:
        return message.integer_value
    if message.type == ParameterType.PARAMETER_BOOL:
        return message.bool_value
    assert message.type == ParameterType.PARAMETER_STRING, message
    return message.string_value


@pytest.mark.parametrize(
    ("node", "old", "new", "name", "value"),
    [
        ("vehicle_estimator", "window_s: 2.0 ", "window_s: 3.5 ", "window_s", 3.5),
        ("speed_monitor", "clear_ratio: 0.6 ", "clear_ratio: 0.7 ", "clear_ratio", 0.7),
    ],
)
def test_config_file_is_applied_in_any_namespace(
    node: str, old: str, new: str, name: str, value: float, tmp_path: Path
) -> None:
    text = (CONFIG / f"{node}.yaml").read_text(encoding="utf-8")
    assert text.count(old) == 1
    edited = tmp_path / f"{node}.yaml"
    edited.write_text(text.replace(old, new), encoding="utf-8")
    want = _file_values(node, edited)
    assert want[name] == value
    ns = f"/params_file/{node}_ns"
    command = [str(BIN / node), "--ros-args", "-r", f"__ns:={ns}", "--params-file", str(edited)]
    with running(command), probe_node() as probe:
        request = GetParameters.Request(names=list(want))
        answer = call(probe, GetParameters, f"{ns}/{node}/get_parameters", request)
        got = {n: _value(v) for n, v in zip(want, answer.values, strict=True)}
    # every value as the file gives it (the monitor's .nan target too), the edited one included
    assert [n for n in want if not _same(got[n], want[n])] == [], (got, want)
