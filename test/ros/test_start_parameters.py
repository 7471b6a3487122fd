"""Start-up parameters of the feeder nodes (in-process): the clock is chosen at start-up, so a
later ``use_sim_time`` change is refused with the reason and the clock stays as it was (a drive
whose timers switched to sim time with no /clock would have a frozen watchdog); values given for
parameters a node does not have (misspelled names) are named in a warning, not dropped silently;
a float parameter takes an integer (``-p rate:=30``) at start-up and later, stored as the DOUBLE it
means; declared ranges are the specs' own, without a made-up far end."""

from __future__ import annotations

import importlib
import sys

import pytest
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter

from feeder_ros.physics.parameters import ParameterSpec

NODES = [
    ("feeder_ros.nodes.drive_interface", "DriveInterface"),
    ("feeder_ros.nodes.manual_drive", "ManualDrive"),
    ("feeder_ros.nodes.platform_simulator", "PlatformSimulator"),
    ("feeder_ros.nodes.speed_monitor", "SpeedMonitorNode"),
    ("feeder_ros.nodes.vehicle_estimator", "VehicleEstimatorNode"),
]


@pytest.mark.parametrize(("module", "name"), NODES)
@pytest.mark.parametrize("at_start", [False, True])
def test_use_sim_time_is_fixed_at_start(module: str, name: str, at_start: bool) -> None:
    node_class = getattr(importlib.import_module(module), name)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        overrides = [Parameter("use_sim_time", value=at_start)]
        if name == "PlatformSimulator" and at_start:
            overrides.append(Parameter("real_time_factor", value=1.0))
        node = node_class(context=context, parameter_overrides=overrides)
        try:
            [result] = node.set_parameters([Parameter("use_sim_time", value=not at_start)])
            assert not result.successful
            assert result.reason == (
                f"use_sim_time={not at_start!r}: this node's clock is chosen at start-up "
                f"(use_sim_time={at_start}); restart the node to change it"
            )
            assert node.get_parameter("use_sim_time").value is at_start
            assert node.get_clock().ros_time_is_active is at_start
            [same] = node.set_parameters([Parameter("use_sim_time", value=at_start)])
            assert same.successful  # setting the value in force is no change
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


@pytest.mark.parametrize(("module", "name"), NODES)
def test_unknown_start_up_parameters_are_named(
    module: str, name: str, capfd: pytest.CaptureFixture[str]
) -> None:
    node_class = getattr(importlib.import_module(module), name)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        overrides = [
            Parameter("zz_misspelled", value=2.0),
            Parameter("aa_unknown", value="x"),
            Parameter("use_sim_time", value=False),  # rclpy's own: known
            Parameter("qos_overrides./x.subscription.depth", value=5),  # declared with its topic
        ]
        node = node_class(context=context, parameter_overrides=overrides)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    err = capfd.readouterr().err
    assert (
        "ignored: aa_unknown, zz_misspelled given at start-up, but this node has no such "
        "parameter" in err
    )
    assert err.count("ignored:") == 1


def test_simulator_drive_parameters_are_read_only(capfd: pytest.CaptureFixture[str]) -> None:
    """The simulator is driven by drive/command only: its drive parameters (kept so the YAML it
    shares with `feeder sim` loads) are taken at start-up without a warning, and a later change
    is refused instead of being accepted and doing nothing."""
    from feeder_ros.nodes.platform_simulator import PlatformSimulator

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        overrides = [
            Parameter("drive_amplitude_n", value=40.0),
            Parameter("drive_frequency_hz", value=25.0),
        ]
        node = PlatformSimulator(context=context, parameter_overrides=overrides)
        try:
            for name, value in (("drive_amplitude_n", 10.0), ("drive_frequency_hz", 30.0)):
                [result] = node.set_parameters([Parameter(name, value=value)])
                assert not result.successful
                assert name in result.reason
                assert "read-only" in result.reason
                descriptor = node.describe_parameter(name)
                assert descriptor.read_only
                assert "drive/command" in descriptor.description
            assert node.get_parameter("drive_amplitude_n").value == 40.0
            assert node._drive == (25.0, 0.0)  # at rest until a drive command
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert "ignored:" not in capfd.readouterr().err


def test_drive_interface_diagnostics_period_is_read_only() -> None:
    """Its /diagnostics timer is made once: a later change is refused, not taken and ignored."""
    from feeder_ros.nodes.drive_interface import DriveInterface

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        overrides = [Parameter("diagnostics_period_s", value=0.5)]
        node = DriveInterface(context=context, parameter_overrides=overrides)
        try:
            [result] = node.set_parameters([Parameter("diagnostics_period_s", value=2.0)])
            assert not result.successful
            assert "diagnostics_period_s" in result.reason
            assert "read-only" in result.reason
            assert node.get_parameter("diagnostics_period_s").value == 0.5
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


#: per node: a float parameter given an integer at start-up (read-only ones included: start-up
#: values are theirs to take), and one set to an integer later
INTEGER_VALUES = {
    "DriveInterface": ("max_frequency_hz", 250, "min_frequency_hz", 10),
    "ManualDrive": ("frequency_hz", 30, "amplitude_n", 20),
    "PlatformSimulator": ("drive_frequency_hz", 30, "damping_ns_per_m", 2),
    "SpeedMonitorNode": ("publish_rate_hz", 5, "alarm_delay_s", 3),
    "VehicleEstimatorNode": ("publish_rate_hz", 10, "max_drive_frequency_hz", 250),
}


def _stored_double(node: Node, name: str, value: int) -> None:
    stored = node.get_parameter(name)
    assert stored.type_ == Parameter.Type.DOUBLE, (name, stored.type_)
    assert type(stored.value) is float
    assert stored.value == float(value)
    assert node.get_parameters_by_prefix("")[name].value == float(value)
    assert type(node._values[name]) is float  # what the node itself computes with


@pytest.mark.parametrize(("module", "name"), NODES)
def test_float_parameters_take_integers_at_start_up_and_later(module: str, name: str) -> None:
    """``-p drive_frequency_hz:=30`` or ``x: 30`` in a params file gives an INTEGER (as
    ``Parameter(name, value=30)`` here), and so does ``ros2 param set /node x 30``: a float
    parameter takes it as the DOUBLE it means, instead of refusing it for its type."""
    node_class = getattr(importlib.import_module(module), name)
    start, start_value, later, later_value = INTEGER_VALUES[name]
    override = Parameter(start, value=start_value)
    assert override.type_ == Parameter.Type.INTEGER
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = node_class(context=context, parameter_overrides=[override])
        try:
            _stored_double(node, start, start_value)
            if name == "PlatformSimulator":
                assert node._drive == (30.0, 0.0)
            [result] = node.set_parameters([Parameter(later, value=later_value)])
            assert result.successful, result.reason
            _stored_double(node, later, later_value)
            # other types pass unchanged: an integer parameter keeps its type, a bool its own
            [flag] = node.set_parameters([Parameter("use_sim_time", value=False)])
            assert flag.successful
            assert node.get_parameter("use_sim_time").type_ == Parameter.Type.BOOL
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


@pytest.mark.parametrize(("module", "name"), NODES)
def test_declared_ranges_have_no_made_up_end(module: str, name: str) -> None:
    """A parameter with one bound (e.g. > 0 Hz) is described by that bound; a descriptor range
    up to the largest double (or int64) would show in rclpy's refusals as
    "Max: 1.7976931348623157e+308"."""
    node_module = importlib.import_module(module)
    specs: dict[str, ParameterSpec] = node_module.PARAMETERS
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = getattr(node_module, name)(context=context)
        try:
            for spec in specs.values():
                descriptor = node.describe_parameter(spec.name)
                ends = [
                    (bound.from_value, bound.to_value)
                    for bound in (*descriptor.floating_point_range, *descriptor.integer_range)
                ]
                for low, high in ends:
                    assert max(abs(low), abs(high)) < min(sys.float_info.max, 2**62), spec.name
                if spec.minimum is not None and spec.maximum is not None:
                    assert ends == [(spec.minimum, spec.maximum)], spec.name
                else:
                    assert ends == [], spec.name
                if spec.kind in (int, float) and spec.bounds:
                    assert descriptor.additional_constraints == f"must be {spec.bounds}"
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_a_one_sided_range_error_names_the_bound_as_declared() -> None:
    """What ``ros2 param set`` answers for a value below a parameter's only bound, at run time,
    and what a start-up value out of range is refused with."""
    from feeder_ros.nodes.manual_drive import ManualDrive
    from feeder_ros.physics.parameters import ParameterError

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = ManualDrive(context=context)
        try:
            [result] = node.set_parameters([Parameter("frequency_hz", value=-20.0)])
            assert not result.successful
            assert result.reason == "frequency_hz=-20.0 Hz must be > 0 Hz"
            [result] = node.set_parameters([Parameter("amplitude_n", value=-1)])
            assert result.reason == "amplitude_n=-1.0 N must be >= 0 N"
            assert node.get_parameter("frequency_hz").value == 29.6
        finally:
            node.destroy_node()
        with pytest.raises(ParameterError, match=r"^frequency_hz=0 Hz must be > 0 Hz$"):
            ManualDrive(context=context, parameter_overrides=[Parameter("frequency_hz", value=0)])
    finally:
        rclpy.shutdown(context=context)


def test_a_start_up_value_of_another_type_is_refused_by_name() -> None:
    """Start-up values are checked against the table before rclpy declares them: a number for a
    text parameter (``-p modbus.host:=10``) is named as such (only float takes an integer)."""
    from feeder_ros.nodes.drive_interface import DriveInterface
    from feeder_ros.physics.parameters import ParameterError

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        for override, message in (
            (Parameter("modbus.host", value=10), "modbus.host=10 is not a string"),
            (Parameter("backend", value=1), "backend=1 is not one of sim, modbus_tcp"),
            (
                Parameter("speed_model_enabled", value=1),
                "speed_model_enabled=1 is not true or false",
            ),
        ):
            with pytest.raises(ParameterError, match=f"^{message}$"):
                DriveInterface(context=context, parameter_overrides=[override])
    finally:
        rclpy.shutdown(context=context)
