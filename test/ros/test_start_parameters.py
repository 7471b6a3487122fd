"""Start-up parameters of the feeder nodes (in-process): the clock is chosen at start-up, so a
later ``use_sim_time`` change is refused with the reason and the clock stays as it was (a drive
whose timers switched to sim time with no /clock would have a frozen watchdog); values given for
parameters a node does not have (misspelled names) are named in a warning, not dropped silently."""

from __future__ import annotations

import importlib

import pytest
import rclpy
from rclpy.parameter import Parameter

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
