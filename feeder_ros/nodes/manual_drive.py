"""``manual_drive``: publish a fixed drive command from parameters (a hand-held drive for tests).

The cell's real entry point is the drive interface node; this one is for bring-up and bench work:
it publishes ``feeder_ros/DriveCommand`` on ``drive/command`` at ``rate_hz`` with the values of its
parameters, which can be changed while it runs (``ros2 param set``).
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from feeder_ros.msg import DriveCommand
from feeder_ros.node_interfaces import NodeInterface, TopicSpec
from feeder_ros.nodes.ros_parameters import declare_parameters, validator
from feeder_ros.nodes.runner import run_node
from feeder_ros.physics.parameters import ParameterSpec

PARAMETERS: dict[str, ParameterSpec] = {
    spec.name: spec
    for spec in (
        ParameterSpec("enabled", bool, "", "true: drive on; false: no drive force"),
        ParameterSpec(
            "frequency_hz", float, "Hz", "drive frequency", minimum=0.0, exclusive_minimum=True
        ),
        ParameterSpec("amplitude_n", float, "N", "drive force amplitude", minimum=0.0),
        ParameterSpec("amplitude_percent", float, "%", "drive amplitude of full scale", 0.0, 100.0),
        ParameterSpec("ramp_time_s", float, "s", "ramp to a new setting", minimum=0.0),
        ParameterSpec(
            "rate_hz",
            float,
            "Hz",
            "publish rate",
            minimum=0.0,
            maximum=1000.0,
            exclusive_minimum=True,
            read_only=True,
        ),
    )
}
DEFAULTS: dict[str, Any] = {
    "enabled": True,
    "frequency_hz": 29.6,
    "amplitude_n": 40.0,
    "amplitude_percent": 40.0,
    "ramp_time_s": 0.0,
    "rate_hz": 10.0,
}
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

INTERFACE = NodeInterface(
    executable="manual_drive",
    node_name="manual_drive",
    summary="publishes a fixed drive command from its parameters (bring-up and bench work)",
    publishes=(
        TopicSpec(
            "drive/command",
            "feeder_ros/msg/DriveCommand",
            "reliable, depth 10",
            "the drive command, at rate_hz",
        ),
    ),
    parameters=PARAMETERS,
)


class ManualDrive(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(INTERFACE.node_name, **kwargs)
        self._values = declare_parameters(self, PARAMETERS.values(), DEFAULTS)
        self.add_on_set_parameters_callback(validator(PARAMETERS, current=lambda: self._values))
        self.add_post_set_parameters_callback(self._apply)
        topic = INTERFACE.publishes[0].name
        self._publisher = self.create_publisher(DriveCommand, topic, COMMAND_QOS)
        self.create_timer(1.0 / self._values["rate_hz"], self._publish)

    def _apply(self, parameters: list[Any]) -> None:
        for parameter in parameters:
            if parameter.name in PARAMETERS:
                self._values[parameter.name] = parameter.value

    def _publish(self) -> None:
        message = DriveCommand()
        message.header.stamp = self.get_clock().now().to_msg()
        message.enabled = bool(self._values["enabled"])
        message.frequency_hz = float(self._values["frequency_hz"])
        message.amplitude_n = float(self._values["amplitude_n"])
        message.amplitude_percent = float(self._values["amplitude_percent"])
        message.ramp_time_s = float(self._values["ramp_time_s"])
        self._publisher.publish(message)


NODE_CLASS = ManualDrive


def main(args: list[str] | None = None) -> int:
    return run_node(ManualDrive, args)
