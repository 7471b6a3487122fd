"""Declare ROS parameters from a table of :class:`ParameterSpec` and validate changes against it.

Every node keeps one table of its parameters (name, type, unit, range, read-only) instead of
repeating ``declare_parameter``/``get_parameter`` calls; descriptors carry the ranges and units so
that ``ros2 param describe`` shows them, and the on-set callback refuses bad values with a reason.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.node import Node

from feeder_ros.physics.parameters import ParameterError, ParameterSpec

if TYPE_CHECKING:
    from feeder_ros.ros_compat import AnyParameter

_ROS_TYPES = {
    float: ParameterType.PARAMETER_DOUBLE,
    int: ParameterType.PARAMETER_INTEGER,
    bool: ParameterType.PARAMETER_BOOL,
    str: ParameterType.PARAMETER_STRING,
}


def descriptor_for(spec: ParameterSpec) -> ParameterDescriptor:
    """A ParameterDescriptor with the spec's type, unit, range and read-only flag."""
    unit = f" [{spec.unit}]" if spec.unit and spec.unit != "1" else ""
    descriptor = ParameterDescriptor(
        name=spec.name,
        type=_ROS_TYPES[spec.kind],
        description=spec.description + unit,
        read_only=spec.read_only,
    )
    if spec.choices:
        descriptor.additional_constraints = "one of: " + ", ".join(spec.choices)
    if spec.kind is float and (spec.minimum is not None or spec.maximum is not None):
        low = spec.minimum if spec.minimum is not None else -sys.float_info.max
        high = spec.maximum if spec.maximum is not None else sys.float_info.max
        descriptor.floating_point_range = [FloatingPointRange(from_value=low, to_value=high)]
        if spec.exclusive_minimum:
            descriptor.additional_constraints = f"must be > {low:g}"
    elif spec.kind is int and (spec.minimum is not None or spec.maximum is not None):
        low_i = int(spec.minimum) if spec.minimum is not None else -(2**63)
        high_i = int(spec.maximum) if spec.maximum is not None else 2**63 - 1
        descriptor.integer_range = [IntegerRange(from_value=low_i, to_value=high_i)]
    return descriptor


def declare_parameters(
    node: Node, specs: Iterable[ParameterSpec], defaults: Mapping[str, Any]
) -> dict[str, Any]:
    """Declare one ROS parameter per spec (default from ``defaults``); returns the values in force.

    Values given at start-up (``--ros-args -p``, YAML) are validated like later changes; a bad one
    raises :class:`ParameterError` naming it, so the node refuses to start rather than run wrong.
    """
    values: dict[str, Any] = {}
    for spec in specs:
        default = defaults[spec.name]
        if spec.kind is float:
            default = float(default)
        parameter = node.declare_parameter(spec.name, default, descriptor_for(spec))
        values[spec.name] = spec.check(parameter.value)
    _warn_unknown_overrides(node)
    node.add_on_set_parameters_callback(
        _fixed_clock(bool(node.get_parameter("use_sim_time").value))
    )
    return values


def _fixed_clock(
    use_sim_time: bool,
) -> Callable[[list[AnyParameter]], SetParametersResult]:
    """An on-set-parameters callback refusing a change of ``use_sim_time``: the feeder nodes
    choose their clock at start-up (timers, watchdogs, the simulator's /clock publisher), and a
    switch to sim time with no /clock would freeze a drive's watchdog."""

    def callback(parameters: list[AnyParameter]) -> SetParametersResult:
        for parameter in parameters:
            if parameter.name == "use_sim_time" and parameter.value != use_sim_time:
                return SetParametersResult(
                    successful=False,
                    reason=f"use_sim_time={parameter.value!r}: this node's clock is chosen at "
                    f"start-up (use_sim_time={use_sim_time}); restart the node to change it",
                )
        return SetParametersResult(successful=True)

    return callback


def _warn_unknown_overrides(node: Node) -> None:
    """Name the start-up values (``-p``, params files) for parameters this node does not have:
    rclpy drops them silently, so a misspelled name would leave the default in force unnoticed."""
    overrides = getattr(node, "_parameter_overrides", {})  # rclpy keeps them there
    unknown = sorted(
        name
        for name in overrides
        # QoS overrides are declared later, with the publisher or subscription they configure
        if not name.startswith("qos_overrides.") and not node.has_parameter(name)
    )
    if unknown:
        node.get_logger().warning(
            f"ignored: {', '.join(unknown)} given at start-up, but this node has no such "
            "parameter (misspelled? the README's node tables list the parameters)"
        )


def validator(
    specs: Mapping[str, ParameterSpec],
    check_all: Callable[[dict[str, Any]], object] | None = None,
    current: Callable[[], Mapping[str, Any]] | None = None,
) -> Callable[[list[AnyParameter]], SetParametersResult]:
    """An on-set-parameters callback that validates each value, then the combination.

    ``check_all(values)`` sees the current values with the proposed changes applied and raises
    ParameterError/ValueError for combinations that are invalid (e.g. mu_d > mu_s). The callback
    has no side effects: nodes apply accepted changes in a post-set callback.
    """

    def callback(parameters: list[AnyParameter]) -> SetParametersResult:
        proposed = dict(current()) if current is not None else {}
        try:
            for parameter in parameters:
                spec = specs.get(parameter.name)
                if spec is None:
                    continue  # use_sim_time (see _fixed_clock) and others rclpy manages itself
                proposed[parameter.name] = spec.check(parameter.value)
            if check_all is not None:
                check_all(proposed)
        except (ParameterError, ValueError) as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    return callback
