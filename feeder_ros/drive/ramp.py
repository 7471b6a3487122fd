"""Linear soft-start/soft-stop ramp of (frequency, amplitude) on a caller-supplied time base.

The time base is the node clock in seconds (sim time works): the ramp never reads a clock itself.
Both axes move linearly and arrive together; the duration is the requested ramp time lengthened
so that neither axis exceeds its maximum rate. At zero amplitude the frequency is free (no force
is applied), so a start from standstill steps the frequency and ramps only the amplitude.
"""

from __future__ import annotations

from dataclasses import dataclass

from feeder_ros.drive.limits import DriveLimits

__all__ = ["DrivePoint", "Ramp"]


@dataclass(frozen=True)
class DrivePoint:
    frequency_hz: float
    amplitude_percent: float


class Ramp:
    """``Ramp(limits)``; ``retarget(now, target, ramp_time)``, ``value(now)``, ``done(now)``."""

    def __init__(self, limits: DriveLimits, frequency_hz: float | None = None) -> None:
        self.limits = limits
        start = DrivePoint(limits.min_frequency_hz if frequency_hz is None else frequency_hz, 0.0)
        self._start = start
        self._target = start
        self._t0 = 0.0
        self._duration = 0.0

    @property
    def target(self) -> DrivePoint:
        return self._target

    def retarget(self, now_s: float, target: DrivePoint, ramp_time_s: float = 0.0) -> float:
        """Ramp from the value at ``now_s`` to ``target``; returns the ramp time used [s]."""
        current = self.value(now_s)
        if current.amplitude_percent == 0.0:
            current = DrivePoint(target.frequency_hz, 0.0)  # frequency is free at zero force
        duration = max(
            ramp_time_s,
            self.limits.minimum_ramp_time_s(
                current.frequency_hz,
                current.amplitude_percent,
                target.frequency_hz,
                target.amplitude_percent,
            ),
        )
        self._start, self._target, self._t0, self._duration = current, target, now_s, duration
        return duration

    def to_zero(self, now_s: float) -> float:
        """Soft stop: amplitude to zero at the maximum amplitude rate, frequency held."""
        current = self.value(now_s)
        return self.retarget(now_s, DrivePoint(current.frequency_hz, 0.0))

    def zero_now(self, now_s: float) -> None:
        """Emergency stop: zero amplitude at once."""
        current = self.value(now_s)
        self._start = self._target = DrivePoint(current.frequency_hz, 0.0)
        self._t0, self._duration = now_s, 0.0

    def value(self, now_s: float) -> DrivePoint:
        """The ramp's value at ``now_s`` (before the start: the start; a clock that jumped back
        holds the start rather than extrapolating)."""
        if self._duration <= 0.0 or now_s >= self._t0 + self._duration:
            return self._target
        fraction = max(0.0, (now_s - self._t0) / self._duration)
        a, b = self._start, self._target
        return DrivePoint(
            a.frequency_hz + (b.frequency_hz - a.frequency_hz) * fraction,
            a.amplitude_percent + (b.amplitude_percent - a.amplitude_percent) * fraction,
        )

    def done(self, now_s: float) -> bool:
        return self._duration <= 0.0 or now_s >= self._t0 + self._duration

    def remaining_s(self, now_s: float) -> float:
        return max(0.0, self._t0 + self._duration - now_s)
