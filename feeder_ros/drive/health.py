"""The drive interface's health for ``/diagnostics`` (ROS-free): one level and one summary line.

:func:`drive_health` ranks what is wrong, most serious first, so the summary names the one thing
an operator should look at: a latched fault or e-stop (ERROR), a backend fault (ERROR), a backend
not connected, a backend warning, a lost heartbeat (WARN); otherwise the state (OK), with the
pause reason while level control holds feeding. Conditions that only degrade a running drive add
a WARN to an OK drive, appended to the summary: inactive, amplitude regulation not holding its
set point, resonance tracking holding on stale feedback or with its amplitude at the limit.
:func:`drive_values` is the drive's part of the status's key values.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from feeder_ros.drive.backend import BackendStatus, DriveOutput
from feeder_ros.drive.controller import DriveController, DriveState
from feeder_ros.drive.resonance_tracker import TrackerMode, TrackerStatus

__all__ = ["Health", "Level", "drive_health", "drive_values"]


class Level(enum.IntEnum):
    """Same values as diagnostic_msgs/DiagnosticStatus's OK, WARN and ERROR."""

    OK = 0
    WARN = 1
    ERROR = 2


@dataclass(frozen=True)
class Health:
    level: Level
    summary: str

    def warn_if_ok(self, condition: bool, note: str, prefix: bool = False) -> Health:
        """An OK health with ``condition`` becomes WARN, ``note`` appended (or put first)."""
        if not condition or self.level is not Level.OK:
            return self
        return Health(
            Level.WARN, f"{note}: {self.summary}" if prefix else f"{self.summary}; {note}"
        )


def drive_health(
    controller: DriveController,
    backend: BackendStatus,
    now_s: float,
    amplitude_warning: str = "",
    tracking: TrackerStatus | None = None,
) -> Health:
    """See the module docstring."""
    state = controller.state.name.lower()
    if controller.state in (DriveState.FAULT, DriveState.ESTOP):
        health = Health(Level.ERROR, f"{state}: {controller.fault_reason}")
    elif backend.fault:
        health = Health(Level.ERROR, f"backend: {backend.fault}")
    elif not backend.connected:
        health = Health(Level.WARN, "backend not connected")
    elif backend.warning:
        health = Health(Level.WARN, f"{state}; backend: {backend.warning}")
    elif not controller.watchdog.alive(now_s):
        health = Health(Level.WARN, f"{state}; no heartbeat")
    elif controller.paused:
        health = Health(Level.OK, f"{state}: {controller.hold_reason}")
    else:
        health = Health(Level.OK, state)
    health = health.warn_if_ok(
        bool(amplitude_warning), f"amplitude regulation: {amplitude_warning}"
    )
    health = health.warn_if_ok(not controller.active, "inactive", prefix=True)
    if tracking is not None:
        health = health.warn_if_ok(
            tracking.mode is TrackerMode.HOLD,
            "resonance tracking holding: speed feedback stale",
        ).warn_if_ok(
            tracking.mode is TrackerMode.ACTIVE and tracking.amplitude_limited,
            "resonance tracking: amplitude at its limit",
        )
    return health


def drive_values(
    controller: DriveController, backend: BackendStatus, output: DriveOutput, now_s: float
) -> dict[str, str]:
    """The key values of the drive's diagnostic status: its state, the output and set point, the
    heartbeat, the latched fault and the backend (with the controller's actual values when the
    backend reads them back)."""
    age = controller.watchdog.age_s(now_s)
    values = {
        "state": controller.state.name.lower(),
        "active": str(controller.active),
        "output enabled": str(output.enabled),
        "frequency_hz": f"{output.frequency_hz:.3f}",
        "amplitude_percent": f"{output.amplitude_percent:.3f}",
        "amplitude_n": f"{output.amplitude_n:.3f}",
        "target_frequency_hz": f"{controller.set_point.frequency_hz:.3f}",
        "target_amplitude_percent": f"{controller.set_point.amplitude_percent:.3f}",
        "heartbeat age s": "never" if math.isinf(age) else f"{age:.3f}",
        "heartbeat timeout s": f"{controller.watchdog.timeout_s:g}",
        "fault_reason": controller.fault_reason,
        "backend connected": str(backend.connected),
        "backend fault": backend.fault,
        "backend warning": backend.warning,
        **backend.details,
    }
    if backend.actual_frequency_hz is not None:
        values["controller actual_frequency_hz"] = f"{backend.actual_frequency_hz:.3f}"
    if backend.actual_amplitude_percent is not None:
        values["controller actual_amplitude_percent"] = f"{backend.actual_amplitude_percent:.3f}"
    return values
