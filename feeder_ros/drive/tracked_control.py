"""Resonance tracking coordinated with the drive controller (ROS-free).

:class:`TrackedControl` decides when the resonance tracker
(:class:`~feeder_ros.drive.resonance_tracker.ResonanceTracker`) runs, and applies its set
points through :func:`apply_loop_point`, the one way every outer loop (the tracker, the speed
trim) moves the drive: the controller's own checks, limits and ramps, with target-speed mode and
its target kept.

- **When it runs**: ``enabled``, the drive active, no fault latched, in target-speed mode and
  started. Otherwise it stops; stopped or faulted in target-speed mode, the tracked point becomes
  the stored set point (a later start resumes from the peak); left by set_drive, nothing is held.
- **Starting**: from the controller's set point (the speed model's) once the drive may run; a start
  the tracker refuses is not retried until the set point, the settings or the limits change.
- **What it says**: every decision worth a log line goes to ``log(severity, text)`` (severity
  ``"info"``, ``"warning"``, or ``"repeating"`` for a warning that may come every tick, which the
  shell throttles); :meth:`TrackedControl.values` gives the diagnostics' key/values.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from feeder_ros.drive.controller import DriveAnswer, DriveController
from feeder_ros.drive.limits import DriveLimits, Outcome
from feeder_ros.drive.resonance_tracker import (
    ResonanceTracker,
    TrackerCommand,
    TrackerMode,
    TrackerSettings,
    TrackerStatus,
)

__all__ = ["Log", "TrackedControl", "apply_loop_point"]

#: ``log(severity, text)``: severity "info", "warning" or "repeating" (a warning to throttle)
Log = Callable[[str, str], None]
_MODE_NAMES = {mode: mode.name.lower() for mode in TrackerMode}


def apply_loop_point(
    controller: DriveController, now_s: float, frequency_hz: float, amplitude_percent: float
) -> DriveAnswer:
    """An outer loop's set point through the controller's checks, limits and ramps (no ramp time
    of its own: the rate limits set it), with target-speed mode and its target kept."""
    speed_mode, target = controller.speed_mode, controller.target_speed_mps
    answer = controller.set_drive(now_s, frequency_hz, amplitude_percent, 0.0)
    controller.speed_mode, controller.target_speed_mps = speed_mode, target
    return answer


class TrackedControl:
    """``TrackedControl(settings, limits, log)``: see the module docstring. ``enabled`` is the
    ``tracking.enabled`` parameter, read at every tick."""

    def __init__(self, settings: TrackerSettings, limits: DriveLimits, log: Log) -> None:
        self.tracker = ResonanceTracker(settings, limits)
        self.enabled = False
        self.note = "waiting for target-speed mode"  # why tracking is not active
        self._refused: tuple[float, float, float] | None = None  # a start point refused
        self._logged_mode = TrackerMode.OFF
        self._log = log

    @property
    def active(self) -> bool:
        """Tracking owns the set point (ACTIVE or HOLD)."""
        return self.tracker.mode is not TrackerMode.OFF

    def blocker(self, controller: DriveController) -> str:
        """Why tracking may not run now ('' when it may)."""
        if not self.enabled:
            return "tracking.enabled is false"
        if not controller.active:
            return "drive interface not active"
        if controller.fault_reason:
            return f"latched: {controller.fault_reason}"
        if not controller.speed_mode:
            return "not in target-speed mode (set_target_speed)"
        if not controller.running:
            return "not running (start)"
        return ""

    def tick(self, controller: DriveController, now_s: float) -> None:
        blocker = self.blocker(controller)
        if blocker:
            self.stop(controller, now_s, blocker, hold=controller.speed_mode)
            self.note = blocker
            return
        tracker = self.tracker
        command: TrackerCommand | None
        if tracker.mode is TrackerMode.OFF:
            point = controller.set_point
            start = (point.frequency_hz, point.amplitude_percent, controller.target_speed_mps)
            if start == self._refused:
                return
            ready_s = now_s + controller.ramp.remaining_s(now_s)
            command = tracker.start(now_s, *start, ready_s=ready_s)
            if command is None:
                self._refused = start
                self.note = tracker.status(now_s).reason
                self._log("warning", f"resonance tracking cannot start: {self.note}")
                return
            self._refused, self.note = None, ""
            self._log(
                "info",
                f"resonance tracking started at {point.frequency_hz:.3f} Hz, "
                f"{point.amplitude_percent:.2f} % for {controller.target_speed_mps:g} m/s",
            )
        else:
            command = tracker.update(now_s)
        if command is not None:
            self._apply(controller, now_s, command)
        self._log_mode(now_s)

    def stop(self, controller: DriveController, now_s: float, reason: str, hold: bool) -> None:
        """Stop tracking; ``hold``: its point becomes the stored set point (drive active, no
        fault)."""
        command = self.tracker.stop(reason)
        if command is not None:
            self._log(
                "info",
                f"resonance tracking stopped ({reason}) at {command.frequency_hz:.3f} Hz, "
                f"{command.amplitude_percent:.2f} %",
            )
            if hold and controller.active and not controller.fault_reason:
                self._apply(controller, now_s, command)
        self._log_mode(now_s)

    def new_target(self) -> None:
        """A new target speed: tracking restarts from the speed model's set point next tick."""
        self.tracker.stop("new target speed")
        self._refused = None

    def settings_changed(
        self,
        controller: DriveController,
        now_s: float,
        settings: TrackerSettings | None,
        limits: DriveLimits | None,
    ) -> None:
        """New tracker settings and/or limits (None: unchanged): a refused start may work now."""
        self._refused = None
        for command in (
            self.tracker.update_settings(settings, now_s) if settings is not None else None,
            self.tracker.update_limits(limits, now_s) if limits is not None else None,
        ):
            if command is not None:
                self._apply(controller, now_s, command)

    def feedback(self, t_s: float, speed_mps: float) -> None:
        self.tracker.feedback(t_s, speed_mps)

    def status(self, now_s: float) -> TrackerStatus:
        return self.tracker.status(now_s)

    def values(self, now_s: float, feedback: str) -> dict[str, str]:
        """The diagnostics' key/values (``feedback``: the feedback topic and type, as shown)."""
        tracking = self.tracker.status(now_s)
        mode = _MODE_NAMES[tracking.mode]
        note = tracking.reason if tracking.mode is not TrackerMode.OFF else self.note
        age = tracking.feedback_age_s
        return {
            "resonance tracking": f"{mode}: {note}" if note else mode,
            "tracking feedback": feedback,
            "tracked_frequency_hz": f"{tracking.centre_frequency_hz:.3f}",
            "tracked_amplitude_percent": f"{tracking.amplitude_percent:.3f}",
            "tracking measured_speed_mps": f"{tracking.measured_speed_mps:.6g}",
            "tracking relative gradient 1/Hz": f"{tracking.gradient_per_hz:.4g}",
            "tracking relative speed error": f"{tracking.speed_error:.4g}",
            "tracking cycles": str(tracking.cycles),
            "tracking feedback age s": "never" if math.isinf(age) else f"{age:.3f}",
            "tracking amplitude limited": str(tracking.amplitude_limited),
        }

    def _apply(self, controller: DriveController, now_s: float, command: TrackerCommand) -> None:
        answer = apply_loop_point(
            controller, now_s, command.frequency_hz, command.amplitude_percent
        )
        if answer.outcome is Outcome.REFUSED:
            self._log("repeating", f"resonance tracking set point refused: {answer.reason}")

    def _log_mode(self, now_s: float) -> None:
        tracker = self.tracker
        if tracker.mode is self._logged_mode:
            return
        previous, self._logged_mode = self._logged_mode, tracker.mode
        status = tracker.status(now_s)
        if status.mode is TrackerMode.HOLD:
            self._log("warning", f"resonance tracking: {status.reason}")
        elif previous is TrackerMode.HOLD and status.mode is TrackerMode.ACTIVE:
            self._log("info", "resonance tracking: speed feedback back, tracking again")
