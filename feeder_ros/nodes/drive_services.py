"""The drive interface's services: ``start``, ``stop``, ``emergency_stop``, ``reset_fault``
(``std_srvs/Trigger``), ``set_drive`` and ``set_target_speed`` (``feeder_ros/srv``).

Each turns a request into one call on the node's
:class:`~feeder_ros.drive.controller.DriveController` (ROS-free: it decides accepted, clamped or
refused, with the reason) and its answer into the response. Unconfigured, the node refuses
``start``, ``reset_fault`` and the set points, saying so; ``stop`` and ``emergency_stop`` succeed
(the output is off). :class:`DriveServices` is a mixin of
:class:`~feeder_ros.nodes.drive_interface.DriveInterface`, which owns the controller, backend,
tracked control and part feeding it reads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from std_srvs.srv import Trigger

from feeder_ros.drive.limits import Outcome
from feeder_ros.srv import SetDrive, SetTargetSpeed

if TYPE_CHECKING:
    from rclpy.lifecycle import LifecycleNode

    from feeder_ros.drive.backend import DriveBackend
    from feeder_ros.drive.controller import DriveController
    from feeder_ros.drive.tracked_control import TrackedControl
    from feeder_ros.nodes.drive_feeding import Feeding

    _Node = LifecycleNode
else:
    _Node = object  # at run time the node class that mixes this in is the LifecycleNode


class DriveServices(_Node):
    """The services' callbacks, registered by :meth:`_create_services` (on the node's state)."""

    _controller: DriveController | None
    _backend: DriveBackend | None
    _tracked: TrackedControl | None
    _feeding: Feeding
    _values: dict[str, Any]

    if TYPE_CHECKING:

        def _now(self) -> float: ...
        def _tick(self) -> None: ...

    def _create_services(self) -> None:
        self.create_service(Trigger, "start", self._on_start)
        self.create_service(Trigger, "stop", self._on_stop)
        self.create_service(SetDrive, "set_drive", self._on_set_drive)
        self.create_service(SetTargetSpeed, "set_target_speed", self._on_set_target_speed)
        self.create_service(Trigger, "reset_fault", self._on_reset_fault)
        self.create_service(Trigger, "emergency_stop", self._on_emergency_stop)

    def _not_configured(self) -> str:
        return "drive interface not configured (lifecycle: configure, then activate)"

    def _on_start(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        controller, backend = self._controller, self._backend
        if controller is None or backend is None:
            response.success, response.message = False, self._not_configured()
            return response
        status = backend.status()
        if not status.connected:
            response.success = False
            response.message = f"backend not connected: {status.fault or status.warning}"
            return response
        answer = controller.start(self._now())
        response.success, response.message = answer.success, answer.message
        if answer.success and status.warning:
            response.message = f"{answer.message} (backend: {status.warning})"
        return response

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        if self._controller is None:
            response.success, response.message = True, "not configured: output is off"
            return response
        answer = self._controller.stop(self._now())
        response.success, response.message = answer.success, answer.message
        return response

    def _on_emergency_stop(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        if self._controller is None:
            response.success, response.message = True, "not configured: output is off"
            return response
        answer = self._controller.emergency_stop(self._now())
        self._tick()  # the zero goes out now, not at the next tick
        self.get_logger().warning(f"emergency stop: {answer.message}")
        response.success, response.message = answer.success, answer.message
        return response

    def _on_reset_fault(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        controller, backend = self._controller, self._backend
        if controller is None or backend is None:
            response.success, response.message = False, self._not_configured()
            return response
        answer = controller.reset_fault(self._now())
        if answer.success:
            self._feeding.reset_fault(self._now())
        message = answer.message
        if not answer.success and controller.backend_fault:
            acknowledge = getattr(backend, "acknowledge_fault", None)
            if acknowledge is not None:
                acknowledge()
                message += "; alarm reset sent to the controller, call reset_fault again"
        response.success, response.message = answer.success, message
        return response

    def _on_set_drive(self, request: SetDrive.Request, response: SetDrive.Response) -> Any:
        if self._controller is None:
            response.result, response.reason = SetDrive.Response.REFUSED, self._not_configured()
            return response
        answer = self._controller.set_drive(
            self._now(), request.frequency_hz, request.amplitude_percent, request.ramp_time_s
        )
        response.result = int(answer.outcome)
        response.reason = answer.reason
        response.frequency_hz = answer.frequency_hz
        response.amplitude_percent = answer.amplitude_percent
        response.ramp_time_s = answer.ramp_time_s
        return response

    def _on_set_target_speed(
        self, request: SetTargetSpeed.Request, response: SetTargetSpeed.Response
    ) -> Any:
        if self._controller is None:
            response.result = SetTargetSpeed.Response.REFUSED
            response.reason = self._not_configured()
            return response
        answer = self._controller.set_target_speed(
            self._now(), request.speed_mps, request.ramp_time_s
        )
        reason = answer.reason
        if answer.outcome is not Outcome.REFUSED and self._tracked is not None:
            # a new target: tracking restarts from the speed model's set point at the next tick
            self._tracked.new_target()
            if self._values["tracking.enabled"]:
                note = "resonance tracking refines frequency and amplitude from this set point"
                reason = f"{reason}; {note}" if reason else note
        response.result = int(answer.outcome)
        response.reason = reason
        response.frequency_hz = answer.frequency_hz
        response.amplitude_percent = answer.amplitude_percent
        response.predicted_speed_mps = answer.predicted_speed_mps
        return response
