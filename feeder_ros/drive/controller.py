"""The drive interface's state machine: what the cell controller may ask, what reaches the drive.

:class:`DriveController` is driven by the node with the node clock's time in seconds: service
requests become method calls that answer accepted / clamped / refused with a reason, and
:meth:`DriveController.tick` returns the output for the backend. Whatever was requested, the
output is a fresh ramp value inside the limits; a lost heartbeat, a backend fault or an e-stop
takes it to zero.

States (``DriveState``): IDLE (output off), RAMPING (moving toward the set point or to zero),
RUNNING (at the set point), FAULT (watchdog/backend/limits; output ramped to zero; latched until
reset), ESTOP (output zeroed at once; latched until reset), PAUSED (started, but feeding held by
:meth:`DriveController.hold`, e.g. track level control with a full track: the output ramps to zero
and returns to the set point when every hold is released).

**Amplitude correction** (:meth:`DriveController.scale_amplitude`): an inner loop (vibration-
amplitude regulation) may scale the output amplitude: the output is the ramp value times the
scale, clamped to ``max_amplitude_percent``, the scale slewed so that the output changes no
faster than ``max_amplitude_rate_percent_per_s``. The set point, and every outer loop writing it
(set_drive, target-speed mode, its trim, resonance tracking), stays unscaled. An output that goes
off forgets the correction: the next start begins at the set point itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from feeder_ros.drive.backend import DriveOutput
from feeder_ros.drive.limits import DriveLimits, Outcome, clamp_set_point
from feeder_ros.drive.ramp import DrivePoint, Ramp
from feeder_ros.drive.speed_model import SpeedModel
from feeder_ros.drive.watchdog import Watchdog

__all__ = ["Answer", "DriveAnswer", "DriveController", "DriveState", "SpeedAnswer"]


class DriveState(IntEnum):
    """Same values as feeder_ros/DriveState's STATE_* constants."""

    IDLE = 0
    RAMPING = 1
    RUNNING = 2
    FAULT = 3
    ESTOP = 4
    PAUSED = 5


@dataclass(frozen=True)
class Answer:
    """A std_srvs/Trigger answer."""

    success: bool
    message: str


@dataclass(frozen=True)
class DriveAnswer:
    outcome: Outcome
    reason: str
    frequency_hz: float = 0.0
    amplitude_percent: float = 0.0
    ramp_time_s: float = 0.0


@dataclass(frozen=True)
class SpeedAnswer:
    outcome: Outcome
    reason: str
    frequency_hz: float = 0.0
    amplitude_percent: float = 0.0
    predicted_speed_mps: float = 0.0


class DriveController:
    """``DriveController(limits, heartbeat_timeout_s, speed_model, clamp_unreachable_speed)``."""

    def __init__(
        self,
        limits: DriveLimits,
        heartbeat_timeout_s: float = 2.0,
        speed_model: SpeedModel | None = None,
        clamp_unreachable_speed: bool = False,
    ) -> None:
        self.limits = limits
        self.watchdog = Watchdog(heartbeat_timeout_s)
        self.speed_model = speed_model
        self.clamp_unreachable_speed = clamp_unreachable_speed
        self.ramp = Ramp(limits)
        self.active = False
        self.running = False  # the cell controller wants output (start .. stop)
        self.set_point = DrivePoint(limits.min_frequency_hz, 0.0)
        self.set_ramp_time_s = 0.0
        self.speed_mode = False
        self.target_speed_mps = 0.0
        self._latched: DriveState | None = None  # FAULT or ESTOP
        self.fault_reason = ""
        self.backend_fault = ""
        self._state = DriveState.IDLE
        self._holds: dict[str, str] = {}  # who holds feeding (level control, ...) -> why
        self.amplitude_scale = 1.0  # the inner amplitude loop's correction in force
        self._scale_target = 1.0
        self._last_tick_s: float | None = None

    # -- inputs from the ROS shell --------------------------------------------------------------
    def heartbeat(self, now_s: float) -> None:
        self.watchdog.feed(now_s)

    def activate(self, now_s: float) -> None:
        self.active = True

    def deactivate(self, now_s: float) -> float:
        """Output permission withdrawn: ramp to zero (output off when there); returns ramp time."""
        self.active = False
        self.running = False
        return self.ramp.to_zero(now_s)

    def update_limits(self, limits: DriveLimits, now_s: float) -> str:
        """New limits (a parameter change): the set point is clamped into them and the ramp
        continues from the present output under the new rates; returns the clamping note."""
        self.limits = limits
        self.ramp.limits = limits
        clamped = clamp_set_point(
            limits, self.set_point.frequency_hz, self.set_point.amplitude_percent, 0.0
        )
        self.set_point = DrivePoint(clamped.frequency_hz, clamped.amplitude_percent)
        if self.running and not self._holds:
            self.ramp.retarget(now_s, self.set_point, self.set_ramp_time_s)
        else:
            # not running (or feeding held): the output heads for zero force at a frequency
            # inside the new limits (an idle output left at a frequency the limits now exclude
            # would fail the guard and latch a fault on a drive that does nothing)
            value = self.ramp.value(now_s)
            inside = clamp_set_point(limits, value.frequency_hz, 0.0, 0.0).frequency_hz
            target = self.ramp.target
            if value.amplitude_percent > 0.0 or (target.frequency_hz, target.amplitude_percent) != (
                inside,
                0.0,
            ):
                self.ramp.retarget(now_s, DrivePoint(inside, 0.0))
        return clamped.reason

    def set_backend_fault(self, now_s: float, reason: str) -> None:
        """The backend reports a fault (link lost, controller alarm) or, with "", its end."""
        self.backend_fault = reason
        if reason:
            self.fault(now_s, f"backend: {reason}", immediate=True)

    def fault(self, now_s: float, reason: str, immediate: bool = False) -> None:
        """Latch FAULT: the output ramps to zero (``immediate``: zero at once)."""
        if self._latched is DriveState.ESTOP:
            return
        if self._latched is DriveState.FAULT and self.fault_reason == reason:
            return
        self._latched = DriveState.FAULT
        self.fault_reason = reason
        self.running = False
        if immediate:
            self.ramp.zero_now(now_s)
        else:
            self.ramp.to_zero(now_s)

    def hold(self, now_s: float, source: str, reason: str) -> None:
        """Pause feeding for ``source`` (the output ramps to zero; ``running`` is kept, so the
        drive resumes when every hold is released). A new reason from the same source is kept."""
        held = bool(self._holds)
        self._holds[source] = reason
        if not held and self.running:
            self.ramp.to_zero(now_s)

    def release(self, now_s: float, source: str) -> None:
        """End ``source``'s hold; with no hold left, a started drive ramps back to its set point."""
        if self._holds.pop(source, None) is not None and not self._holds and self.running:
            self.ramp.retarget(now_s, self.set_point, self.set_ramp_time_s)

    @property
    def latched(self) -> DriveState | None:
        """FAULT or ESTOP while one is latched (at once, before the next :meth:`tick`)."""
        return self._latched

    @property
    def paused(self) -> bool:
        """Started, with feeding held."""
        return self.running and bool(self._holds)

    @property
    def hold_reason(self) -> str:
        return "; ".join(self._holds.values())

    # -- services -------------------------------------------------------------------------------
    def _latched_refusal(self) -> str:
        if self._latched is None:
            return ""
        name = "emergency stop" if self._latched is DriveState.ESTOP else "fault"
        return f"{name} latched ({self.fault_reason}): call reset_fault first"

    def _heartbeat_refusal(self, now_s: float) -> str:
        if self.watchdog.alive(now_s):
            return ""
        age = self.watchdog.age_s(now_s)
        seen = "no heartbeat received" if math.isinf(age) else f"last heartbeat {age:.2f} s ago"
        return f"{seen} (timeout {self.watchdog.timeout_s:g} s): send heartbeats first"

    def set_drive(
        self, now_s: float, frequency_hz: float, amplitude_percent: float, ramp_time_s: float
    ) -> DriveAnswer:
        refusal = self._latched_refusal() or ("" if self.active else "drive interface not active")
        if not refusal and self.running:
            refusal = self._heartbeat_refusal(now_s)
        if refusal:
            return DriveAnswer(Outcome.REFUSED, refusal)
        clamped = clamp_set_point(self.limits, frequency_hz, amplitude_percent, ramp_time_s)
        if clamped.outcome is Outcome.REFUSED:
            return DriveAnswer(Outcome.REFUSED, clamped.reason)
        self.speed_mode = False
        return self._apply(
            now_s,
            clamped.outcome,
            [clamped.reason] if clamped.reason else [],
            DrivePoint(clamped.frequency_hz, clamped.amplitude_percent),
            ramp_time_s,
        )

    def _apply(
        self, now_s: float, outcome: Outcome, notes: list[str], target: DrivePoint, ramp_s: float
    ) -> DriveAnswer:
        self.set_point = target
        self.set_ramp_time_s = ramp_s
        if self.running and not self._holds:
            used = self.ramp.retarget(now_s, target, ramp_s)
        else:
            used = max(
                ramp_s,
                self.limits.minimum_ramp_time_s(
                    target.frequency_hz, 0.0, target.frequency_hz, target.amplitude_percent
                ),
            )
            notes.append(
                f"set point stored; feeding paused ({self.hold_reason})"
                if self.running
                else "set point stored; start to drive"
            )
        if used > ramp_s + 1e-12:
            notes.append(
                f"ramp time lengthened from {ramp_s:g} s to {used:.3f} s by the ramp-rate limits"
            )
        return DriveAnswer(
            outcome, "; ".join(notes), target.frequency_hz, target.amplitude_percent, used
        )

    def set_target_speed(self, now_s: float, speed_mps: float, ramp_time_s: float) -> SpeedAnswer:
        refusal = self._latched_refusal() or ("" if self.active else "drive interface not active")
        if not refusal and self.running:
            refusal = self._heartbeat_refusal(now_s)
        if not refusal and self.speed_model is None:
            refusal = "no speed model (speed_model_enabled is false)"
        if not refusal and not (math.isfinite(speed_mps) and math.isfinite(ramp_time_s)):
            refusal = f"speed_mps={speed_mps!r}, ramp_time_s={ramp_time_s!r} must be finite"
        if not refusal and ramp_time_s < 0.0:
            refusal = f"ramp_time_s={ramp_time_s:g} must be >= 0"
        if refusal or self.speed_model is None:
            return SpeedAnswer(Outcome.REFUSED, refusal)
        choice = self.speed_model.choose(speed_mps)
        outcome, notes = Outcome.ACCEPTED, []
        if choice is None:
            low, high = self.speed_model.reachable_range()
            unreachable = (
                f"speed {speed_mps:g} m/s unreachable within the limits; "
                f"reachable {low:.4g} .. {high:.4g} m/s"
            )
            if not self.clamp_unreachable_speed:
                return SpeedAnswer(Outcome.REFUSED, unreachable)
            choice = self.speed_model.nearest(speed_mps)
            outcome = Outcome.CLAMPED
            notes.append(
                f"{unreachable}; driving the nearest, {choice.predicted_speed_mps:.4g} m/s"
            )
        clamped = clamp_set_point(
            self.limits, choice.frequency_hz, choice.amplitude_percent, ramp_time_s
        )
        if clamped.outcome is Outcome.REFUSED:  # pragma: no cover - the model's grid is in limits
            return SpeedAnswer(Outcome.REFUSED, clamped.reason)
        if clamped.reason:
            notes.append(clamped.reason)
            outcome = Outcome.CLAMPED
        answer = self._apply(
            now_s,
            outcome,
            notes,
            DrivePoint(clamped.frequency_hz, clamped.amplitude_percent),
            ramp_time_s,
        )
        self.speed_mode = True
        self.target_speed_mps = speed_mps
        return SpeedAnswer(
            answer.outcome,
            answer.reason,
            answer.frequency_hz,
            answer.amplitude_percent,
            choice.predicted_speed_mps,
        )

    def start(self, now_s: float) -> Answer:
        refusal = self._latched_refusal() or ("" if self.active else "drive interface not active")
        refusal = refusal or self._heartbeat_refusal(now_s)
        if not refusal and self.set_point.amplitude_percent <= 0.0:
            refusal = "set point amplitude is 0 %: call set_drive or set_target_speed first"
        if refusal:
            return Answer(False, refusal)
        self.running = True
        sp = self.set_point
        if self._holds:
            self.ramp.to_zero(now_s)
            return Answer(
                True,
                f"started at {sp.frequency_hz:g} Hz, {sp.amplitude_percent:g} %; feeding paused "
                f"({self.hold_reason}), resumes when it clears",
            )
        used = self.ramp.retarget(now_s, self.set_point, self.set_ramp_time_s)
        return Answer(
            True, f"ramping to {sp.frequency_hz:g} Hz, {sp.amplitude_percent:g} % in {used:.3f} s"
        )

    def stop(self, now_s: float) -> Answer:
        was_running = self.running
        self.running = False
        used = self.ramp.to_zero(now_s)
        if not was_running and used == 0.0:
            return Answer(True, "already stopped")
        return Answer(True, f"ramping to zero in {used:.3f} s")

    def emergency_stop(self, now_s: float, reason: str = "emergency stop requested") -> Answer:
        self.running = False
        self.ramp.zero_now(now_s)
        if self._latched is DriveState.ESTOP:
            return Answer(True, f"emergency stop already latched ({self.fault_reason})")
        self._latched = DriveState.ESTOP
        self.fault_reason = reason
        return Answer(True, "output zeroed; emergency stop latched until reset_fault")

    def reset_fault(self, now_s: float) -> Answer:
        if self._latched is None:
            return Answer(True, "no fault to reset")
        if self.backend_fault:
            return Answer(False, f"backend still faulted: {self.backend_fault}")
        previous = self.fault_reason
        self._latched = None
        self.fault_reason = ""
        return Answer(True, f"cleared ({previous}); output stays off until start")

    def scale_amplitude(self, scale: float) -> None:
        """Scale the output amplitude by ``scale`` (>= 0, finite; 1: none): see the module
        docstring. Raises ValueError naming a bad value."""
        if not (isinstance(scale, float | int) and math.isfinite(scale) and scale >= 0.0):
            raise ValueError(f"amplitude scale {scale!r} must be a finite number >= 0")
        self._scale_target = float(scale)

    def _slewed_scale(self, now_s: float, amplitude_percent: float) -> float:
        """The scale in force at ``now_s``: toward the requested one at the amplitude rate."""
        previous, self._last_tick_s = self._last_tick_s, now_s
        target, scale = self._scale_target, self.amplitude_scale
        if amplitude_percent <= 0.0 or previous is None:
            self.amplitude_scale = target
        else:
            rate = self.limits.max_amplitude_rate_percent_per_s
            step = max(0.0, now_s - previous) * rate / amplitude_percent
            self.amplitude_scale = min(max(target, scale - step), scale + step)
        return self.amplitude_scale

    # -- output ---------------------------------------------------------------------------------
    @property
    def state(self) -> DriveState:
        return self._state

    def tick(self, now_s: float, period_s: float = 0.0) -> DriveOutput:
        """The output at ``now_s``; ``period_s`` (the tick period) becomes the command's ramp time
        while ramping, so a receiver interpolates between ticks instead of stepping."""
        if self.running and not self.watchdog.alive(now_s):
            age = self.watchdog.age_s(now_s)
            self.fault(
                now_s,
                f"heartbeat lost: none for {age:.2f} s (timeout {self.watchdog.timeout_s:g} s)",
            )
        value = self.ramp.value(now_s)
        done = self.ramp.done(now_s)
        if not self._guard(value):
            target = self.ramp.target
            self.fault(
                now_s,
                f"output out of limits: {value.frequency_hz:g} Hz, "
                f"{value.amplitude_percent:g} % heading for {target.frequency_hz:g} Hz, "
                f"{target.amplitude_percent:g} %",
                immediate=True,
            )
            value = self.ramp.value(now_s)
        if self._latched is not None:
            self._state = self._latched
        elif not done:
            self._state = DriveState.RAMPING
        elif self.paused:
            self._state = DriveState.PAUSED
        elif self.running and value.amplitude_percent > 0.0:
            self._state = DriveState.RUNNING
        else:
            self._state = DriveState.IDLE
        enabled = value.amplitude_percent > 0.0
        amplitude = value.amplitude_percent
        if not enabled:  # off: the correction is forgotten
            self.amplitude_scale = self._scale_target = 1.0
        elif self._slewed_scale(now_s, amplitude) != 1.0:
            amplitude = min(amplitude * self.amplitude_scale, self.limits.max_amplitude_percent)
        return DriveOutput(
            enabled=enabled,
            frequency_hz=value.frequency_hz,
            amplitude_percent=amplitude if enabled else 0.0,
            amplitude_n=self.limits.force_n(amplitude) if enabled else 0.0,
            ramp_time_s=period_s if enabled and not done else 0.0,
            time_s=now_s,
        )

    def _guard(self, value: DrivePoint) -> bool:
        """Last check before the backend: the output is finite, its amplitude within 0-100 % and
        its frequency positive, and the ramp heads for a point inside the limits (after a limits
        change the output may still be moving into them; a ramp may cross a forbidden band but
        never rests in one, set points being clamped out of the bands)."""
        f, a = value.frequency_hz, value.amplitude_percent
        target, limits = self.ramp.target, self.limits
        return (
            math.isfinite(f)
            and math.isfinite(a)
            and f > 0.0
            and 0.0 <= a <= 100.0
            and limits.min_frequency_hz - 1e-9
            <= target.frequency_hz
            <= limits.max_frequency_hz + 1e-9
            and target.amplitude_percent <= limits.max_amplitude_percent + 1e-9
        )
