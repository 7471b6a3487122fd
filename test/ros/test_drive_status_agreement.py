"""The drive interface's diagnostics and its drive/state tell the same story: a backend fault
appears in the diagnostics only once the control tick has latched it (drive/state FAULT), never
between the backend noticing it and the tick acting on it. A cell controller that sees
"simulator lost" in /diagnostics and reads drive/state must not find the drive still RUNNING
because the diagnostics timer asked the backend on its own. (In-process: the two timers'
order is set by calling them, which the wire cannot do.)"""

from __future__ import annotations

from typing import Any

import rclpy
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter

from feeder_ros.drive.backend import BackendStatus
from feeder_ros.drive.controller import DriveOutput, DriveState
from feeder_ros.nodes.drive_interface import DriveInterface


class LosingBackend:
    """A backend that is fine until ``lost`` is set, then reports a fault."""

    name = "sim"

    def __init__(self) -> None:
        self.lost = False

    def connect(self) -> None:
        pass

    def write(self, output: DriveOutput) -> None:
        pass

    def disconnect(self) -> None:
        pass

    def status(self) -> BackendStatus:
        return BackendStatus(connected=True, fault="simulator lost: test" if self.lost else "")


def test_diagnostics_name_a_backend_fault_only_once_the_state_is_fault() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = DriveInterface(
            context=context,
            parameter_overrides=[Parameter("speed_model_enabled", value=False)],
        )
        published: list[tuple[int, str, dict[str, str]]] = []

        def record(level: int, summary: str, hardware_id: str, values: dict[str, str]) -> Any:
            published.append((level, summary, values))

        node._publish_status = record  # type: ignore[method-assign]
        try:
            assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
            backend = LosingBackend()
            node._backend = backend
            node._tick()
            node._publish_diagnostics()
            assert published[-1][2]["backend fault"] == ""
            backend.lost = True
            # the backend knows, the tick has not run: the diagnostics still say what the
            # controller (and drive/state) says
            node._publish_diagnostics()
            level, _, values = published[-1]
            assert (values["backend fault"], values["state"]) == ("", "idle")
            node._tick()
            assert node._controller is not None
            assert node._controller.state == DriveState.FAULT
            node._publish_diagnostics()
            level, summary, values = published[-1]
            assert values["backend fault"] == "simulator lost: test"
            assert values["state"] == "fault"
            assert values["fault_reason"] == "backend: simulator lost: test"
            assert level == 2, summary
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
