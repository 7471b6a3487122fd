"""The small interface every drive backend implements, and the simulated-platform backend.

The controller produces one :class:`DriveOutput` per tick; the node hands it to the backend,
which must not block (a fieldbus backend does its I/O in its own thread) and reports its health
as a :class:`BackendStatus` that the node turns into faults and diagnostics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

__all__ = ["NO_SIMULATOR", "BackendStatus", "DriveBackend", "DriveOutput", "SimBackend"]


@dataclass(frozen=True)
class DriveOutput:
    """What the feeder is told now. ``enabled=False`` means no drive force (frequency kept)."""

    enabled: bool
    frequency_hz: float
    amplitude_percent: float
    amplitude_n: float
    ramp_time_s: float = 0.0  # time to move linearly from the previous output to this one
    time_s: float = 0.0  # the time (node clock) this output is the value for: the command stamp


@dataclass(frozen=True)
class BackendStatus:
    """Backend health: ``fault`` is empty when the drive can be driven."""

    connected: bool
    fault: str = ""
    warning: str = ""
    actual_frequency_hz: float | None = None
    actual_amplitude_percent: float | None = None
    details: dict[str, str] = field(default_factory=dict)


class DriveBackend(Protocol):
    name: str

    def connect(self) -> None:
        """Start talking to the drive (may return before the link is up; see status)."""
        ...

    def write(self, output: DriveOutput) -> None:
        """Hand over the latest output; must not block."""
        ...

    def status(self) -> BackendStatus: ...

    def disconnect(self) -> None:
        """Drive off, then stop talking to the drive."""
        ...


#: the sim backend's warning while nothing reads its commands
NO_SIMULATOR = "no subscriber on drive/command: is the platform simulator running?"
WAITING_FOR_SIMULATOR = "waiting for the simulator's first parts/state"


class SimBackend:
    """The platform simulator: every output is published as a freshly stamped DriveCommand by the
    ``publish`` callable the node supplies (the simulator treats an old command as a stop).

    ``listeners`` (optional) counts the subscriptions matched to that publisher. The link is up
    once connected (commands go out, and a simulator that joins later follows the fresh stream),
    but while nothing listens the status carries the warning :data:`NO_SIMULATOR`: a drive
    interface left without its simulator must not look like a running feeder."""

    name = "sim"

    def __init__(
        self,
        publish: Callable[[DriveOutput], None],
        listeners: Callable[[], int] | None = None,
        feedback_age: Callable[[], float | None] | None = None,
        feedback_timeout_s: float = 0.0,
    ) -> None:
        self._publish = publish
        self._listeners = listeners
        # seconds since the simulator last published (None: not yet); a simulator that was live
        # and has been silent for feedback_timeout_s (> 0) is lost: a fault
        self._feedback_age = feedback_age
        self._feedback_timeout_s = feedback_timeout_s
        self._connected = False
        self._last: DriveOutput | None = None

    def connect(self) -> None:
        self._connected = True

    def write(self, output: DriveOutput) -> None:
        if self._connected:
            self._last = output
            self._publish(output)

    def status(self) -> BackendStatus:
        details = {"transport": "drive/command (feeder_ros/DriveCommand)"}
        if self._last is not None:
            details["last command"] = (
                f"enabled={self._last.enabled} {self._last.frequency_hz:.3f} Hz "
                f"{self._last.amplitude_percent:.2f} %"
            )
        warning = fault = ""
        if self._listeners is not None:
            count = self._listeners()
            details["drive/command subscribers"] = str(count)
            if self._connected and count == 0:
                warning = NO_SIMULATOR
        if self._feedback_age is not None and self._feedback_timeout_s > 0.0:
            age = self._feedback_age()
            details["simulator silent for s"] = "never heard" if age is None else f"{age:.2f}"
            if age is None:
                warning = warning or WAITING_FOR_SIMULATOR
            elif age > self._feedback_timeout_s and self._connected:
                fault = (
                    f"simulator lost: no parts/state for {age:.1f} s (sim_feedback_timeout_s="
                    f"{self._feedback_timeout_s:g})"
                )
        return BackendStatus(
            connected=self._connected, warning=warning, fault=fault, details=details
        )

    def disconnect(self) -> None:
        if self._connected and self._last is not None:
            last = self._last
            self._publish(DriveOutput(False, last.frequency_hz, 0.0, 0.0, time_s=last.time_s))
        self._connected = False
