"""Declare ROS parameters from a table of :class:`ParameterSpec` and validate changes against it.

Every node keeps one table of its parameters (name, type, unit, range, read-only) instead of
repeating ``declare_parameter``/``get_parameter`` calls; descriptors carry the ranges and units so
that ``ros2 param describe`` shows them, and the on-set callback refuses bad values with a reason.

A float parameter takes an integer wherever a value comes in (``-p rate:=30``, ``rate: 30`` in a
params file, ``ros2 param set`` sending an INTEGER): it is stored as the DOUBLE it means (30.0),
as every ROS user types whole numbers without a decimal point.
"""

from __future__ import annotations

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
from rclpy.parameter import Parameter

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
    """A ParameterDescriptor with the spec's type, unit, range and read-only flag.

    A range with both ends goes into ``floating_point_range``/``integer_range`` (``ros2 param
    describe`` and rqt show it; rclpy enforces it, and its message names the range as declared).
    A single bound is only described (``additional_constraints``, e.g. "must be >= 0 N") and
    checked by :meth:`ParameterSpec.check`: a range field needs both ends, and a made-up far end
    (the largest double) would show up in rclpy's refusals as "Max: 1.7976931348623157e+308".
    """
    unit = f" [{spec.unit}]" if spec.unit and spec.unit != "1" else ""
    descriptor = ParameterDescriptor(
        name=spec.name,
        type=_ROS_TYPES[spec.kind],
        description=spec.description + unit,
        read_only=spec.read_only,
    )
    if spec.choices:
        descriptor.additional_constraints = "one of: " + ", ".join(spec.choices)
    if spec.kind in (int, float) and spec.bounds:
        descriptor.additional_constraints = f"must be {spec.bounds}"
    if spec.minimum is None or spec.maximum is None:
        return descriptor
    if spec.kind is float:
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(spec.minimum), to_value=float(spec.maximum))
        ]
    elif spec.kind is int:
        descriptor.integer_range = [
            IntegerRange(from_value=int(spec.minimum), to_value=int(spec.maximum))
        ]
    return descriptor


def declare_parameters(
    node: Node, specs: Iterable[ParameterSpec], defaults: Mapping[str, Any]
) -> dict[str, Any]:
    """Declare one ROS parameter per spec (default from ``defaults``); returns the values in force.

    Values given at start-up (``--ros-args -p``, YAML) are validated like later changes; a bad one
    raises :class:`ParameterError` naming it and the range as declared, so the node refuses to
    start rather than run wrong. A float parameter takes an integer, at start-up and later.
    """
    specs = list(specs)
    values: dict[str, Any] = {}
    overrides = _start_up_values(node)
    for spec in specs:
        default = defaults[spec.name]
        if spec.kind is float:
            default = float(default)
        if spec.name in overrides:
            given = overrides[spec.name]
            spec.check(given.value)  # our message (units, the range as declared), not rclpy's
            if spec.kind is float and given.type_ == Parameter.Type.INTEGER:
                overrides[spec.name] = Parameter(spec.name, value=float(given.value))
        parameter = node.declare_parameter(spec.name, default, descriptor_for(spec))
        values[spec.name] = spec.check(parameter.value)
    _warn_unknown_overrides(node)
    node.add_pre_set_parameters_callback(
        _integers_as_doubles(frozenset(spec.name for spec in specs if spec.kind is float))
    )
    node.add_on_set_parameters_callback(
        _fixed_clock(bool(node.get_parameter("use_sim_time").value))
    )
    return values


def _start_up_values(node: Node) -> dict[str, AnyParameter]:
    """The node's start-up values (``-p``, params files, ``parameter_overrides``) by name.

    rclpy (Jazzy's 7.x and Kilted's 9.x alike) keeps them in ``Node._parameter_overrides`` and
    has no public accessor; ``declare_parameter`` takes a parameter's value from there, so an
    integer replaced there by its float is declared as the DOUBLE it means. Without that
    attribute (a future rclpy) an empty dict: rclpy's own type check then refuses an integer,
    loudly, as before."""
    overrides = getattr(node, "_parameter_overrides", None)
    return overrides if isinstance(overrides, dict) else {}


def _integers_as_doubles(
    float_names: frozenset[str],
) -> Callable[[list[AnyParameter]], list[AnyParameter]]:
    """A pre-set-parameters callback turning an INTEGER for a float parameter into its DOUBLE
    (``ros2 param set /node rate 30`` sends an INTEGER): rclpy's type check, the on-set callbacks
    and the stored value then see 30.0. Other parameters pass unchanged, in their order.

    rclpy concatenates the lists its pre-set callbacks return: a node has this one only."""

    def callback(parameters: list[AnyParameter]) -> list[AnyParameter]:
        return [
            Parameter(parameter.name, value=float(parameter.value))
            if parameter.name in float_names and parameter.type_ == Parameter.Type.INTEGER
            else parameter
            for parameter in parameters
        ]

    return callback


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
    overrides = _start_up_values(node)
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
