"""The drive interface's health for ``/diagnostics`` (ROS-free): one level and one summary line.

:func:`drive_health` ranks what is wrong, most serious first, so the summary names the one thing
an operator should look at: a latched fault or e-stop (ERROR), a backend fault (ERROR), a backend
not connected, a backend warning, a lost heartbeat (WARN); otherwise the state (OK), with the
pause reason while level control holds feeding. Conditions that only degrade a running drive add
a WARN to an OK drive, appended to the summary: inactive, amplitude regulation not holding its
set point, resonance tracking holding on stale feedback or with its amplitude at the limit.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from feeder_ros.drive.backend import BackendStatus
from feeder_ros.drive.controller import DriveController, DriveState
from feeder_ros.drive.resonance_tracker import TrackerMode, TrackerStatus

__all__ = ["Health", "Level", "drive_health"]


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
