"""Resonance tracking for target-speed mode: keep the drive on the part-speed peak, and the part
speed at target, as the feeder's springs age and its load changes.

A feeder's part speed peaks near a resonance of its spring-mass system. The speed model
(:mod:`feeder_ros.drive.speed_model`) was computed for the plant as it was; when the stiffness or
the load drifts, the peak moves, the tabulated setting falls onto a flank and the speed drifts off
target. :class:`ResonanceTracker` finds the peak online from measured part speed alone and trims
the amplitude so that the target speed is held there, where the least drive force is needed.
It is ROS-free and clock-free: the caller supplies the time (the node clock, sim time works).

Algorithm: sampled extremum seeking with a square frequency dither, and a PI amplitude trim.

* **Piecewise-constant drive.** A *cycle* is two half-periods of ``dither_period_s / 2``, one at
  ``centre + dither_hz`` and one at ``centre - dither_hz``; the order alternates from cycle to
  cycle (+-, -+, +-, ...), so a slow drift of the speed biases consecutive gradient estimates in
  opposite directions. A half-period starts once the drive's rate-limited ramp to it is done; its
  first ``settle_s`` are discarded (the carrier's transient, and the speed source's own settling:
  the sensorless estimator restarts its statistics at every drive change, and a stick-slip speed
  is only meaningful as a mean over many cycles); the readings stamped after that are averaged.
  A half-period ends once a reading stamped at or after its nominal end has arrived, so a lagging
  speed source delays the tracker instead of feeding it old readings.
* **Frequency (extremum seeking).** With ``p = speed * sign(target)`` (a backward target works
  alike), the cycle's relative speed gradient is ``g = (p+ - p-) / (2 * dither_hz * |target|)``
  [1/Hz]. The centre moves by ``clip(gain_hz2 * g, +-max_step_hz)``, projected into the allowed
  frequency interval it lies in, shrunk by the dither: the dithered frequencies never leave
  ``[min_frequency_hz, max_frequency_hz]`` nor enter a forbidden band (a band is never crossed).
  For a peak shaped like ``v = v0 * (1 - ((f - fp) / w)**2)`` at the target speed,
  ``g = -2 * (f - fp) / w**2``: ``gain_hz2 = w**2 / 2`` is a Newton step, smaller gains
  under-relax.
* **Amplitude (PI trim).** The cycle's mean ``p_c = (p+ + p-) / 2`` is the speed at the centre to
  second order in the dither. The relative error ``e = (|target| - p_c) / |target|`` drives a PI in
  velocity form, ``A += clip(kp * (e - e_prev) + ki * e, +-max_amplitude_step_percent)``, clamped to
  ``[1 % of max_amplitude_percent, max_amplitude_percent]``: the velocity form with the clamp
  cannot wind up. The amplitude changes only between cycles, so both halves of a cycle see the same
  amplitude and the gradient is not confounded with the trim. Together the two loops settle where
  the speed is at its peak over frequency and equal to the target, i.e. at the least amplitude
  that gives the target speed.
* **Stale feedback.** No valid reading for ``feedback_timeout_s`` puts the tracker in ``HOLD``:
  the drive goes to the centre frequency and stays there at the present amplitude (no dither, no
  trim), the partial cycle is discarded, and the first fresh reading starts a new cycle.

The ramp between set points is the drive's (``DriveLimits`` rate limits); the tracker computes its
duration from the same limits to know when a half-period's drive is actually in place.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, fields

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.physics.parameters import is_number

__all__ = [
    "ResonanceTracker",
    "TrackerCommand",
    "TrackerError",
    "TrackerMode",
    "TrackerSettings",
    "TrackerStatus",
]

#: the amplitude trim never goes below this fraction of max_amplitude_percent (0 % is "off")
AMPLITUDE_FLOOR_FRACTION = 0.01
#: a time jump back by more than this restarts the cycle (a restarted or replayed clock)
CLOCK_JUMP_S = 1.0
#: a reading stamped more than this ahead of the tracker's clock (its latest start or update) is
#: ignored: it would count as fresh feedback until the clock reaches it, and keep tracking ACTIVE
#: with no reading coming in (two clocks mixed: sim time and wall time)
FUTURE_STAMP_TOLERANCE_S = 1.0


class TrackerError(ValueError):
    """Tracker settings that cannot work (alone or with the drive limits); the message says why."""


class TrackerMode(enum.IntEnum):
    """Same values as feeder_ros/DriveState's TRACKING_* constants."""

    OFF = 0  #: not tracking (disabled, not in target-speed mode, not running, or cannot dither)
    ACTIVE = 1  #: dithering around the speed peak, amplitude trimmed to the target speed
    HOLD = 2  #: speed feedback stale: centre frequency and amplitude held


@dataclass(frozen=True)
class TrackerSettings:
    """Tuning of :class:`ResonanceTracker` (SI units, amplitude in % of full scale)."""

    dither_hz: float = 0.3  #: frequency offset of each half-period from the centre
    #: one cycle: a half-period on each side of the centre. The sensorless estimator publishes a
    #: mean speed only once its carrier fit has converged at the new setting and half its window
    #: lies after that (about 2.2 s with its defaults): a half-period must be longer
    dither_period_s: float = 8.0
    settle_s: float = 2.6  #: discarded at the start of each half-period
    gain_hz2: float = 1.0  #: centre step per unit relative gradient (1/Hz): Hz^2
    max_step_hz: float = 0.5  #: largest centre step per cycle
    amplitude_kp_percent: float = 5.0  #: amplitude per unit change of relative speed error
    amplitude_ki_percent: float = 20.0  #: amplitude per cycle per unit relative speed error
    max_amplitude_step_percent: float = 5.0  #: largest amplitude change per cycle
    feedback_timeout_s: float = 3.0  #: no valid speed reading this long: HOLD

    def __post_init__(self) -> None:
        for item in fields(self):
            value = getattr(self, item.name)
            if not is_number(value):
                raise TrackerError(f"{item.name}={value!r} is not a number")
            if not math.isfinite(value):
                raise TrackerError(f"{item.name}={value!r} is not finite")
            object.__setattr__(self, item.name, float(value))
        positive = (
            "dither_hz",
            "dither_period_s",
            "max_step_hz",
            "max_amplitude_step_percent",
            "feedback_timeout_s",
        )
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise TrackerError(f"{name}={getattr(self, name)!r} must be > 0")
        for name in ("settle_s", "gain_hz2", "amplitude_kp_percent", "amplitude_ki_percent"):
            if getattr(self, name) < 0.0:
                raise TrackerError(f"{name}={getattr(self, name)!r} must be >= 0")
        if self.settle_s >= self.half_period_s:
            raise TrackerError(
                f"settle_s={self.settle_s:g} s leaves no time to measure: it must be shorter "
                f"than half of dither_period_s={self.dither_period_s:g} s"
            )
        if self.feedback_timeout_s <= self.settle_s:
            raise TrackerError(
                f"feedback_timeout_s={self.feedback_timeout_s:g} s must exceed settle_s="
                f"{self.settle_s:g} s (a speed source may send nothing valid while it settles "
                "after each dither step)"
            )

    @property
    def half_period_s(self) -> float:
        return 0.5 * self.dither_period_s

    def check_against(self, limits: DriveLimits) -> None:
        """Raise :class:`TrackerError` if the dither fits in no allowed frequency interval."""
        widest = max(b - a for a, b in limits.allowed_intervals())
        if 2.0 * self.dither_hz >= widest:
            raise TrackerError(
                f"dither_hz={self.dither_hz:g} Hz needs more than {2.0 * self.dither_hz:g} Hz of "
                f"allowed frequency range; the widest allowed interval is {widest:g} Hz "
                f"({limits.min_frequency_hz:g}-{limits.max_frequency_hz:g} Hz less the "
                "forbidden bands)"
            )


@dataclass(frozen=True)
class TrackerCommand:
    """A new drive set point from the tracker (apply with the drive's own ramp limits)."""

    frequency_hz: float
    amplitude_percent: float


@dataclass(frozen=True)
class TrackerStatus:
    """What the tracker is doing, for DriveState and /diagnostics."""

    mode: TrackerMode
    reason: str  #: why OFF or HOLD; empty when ACTIVE
    centre_frequency_hz: float  #: the tracked peak estimate (nan when OFF)
    amplitude_percent: float  #: the trimmed amplitude (nan when OFF)
    measured_speed_mps: float  #: the latest valid speed reading (nan when none)
    gradient_per_hz: float  #: the last cycle's relative speed gradient (nan before the first)
    speed_error: float  #: the last cycle's relative speed error (nan before the first)
    cycles: int  #: completed cycles since the start
    feedback_age_s: float  #: time since the latest valid reading's stamp (inf when none)
    amplitude_limited: bool  #: the trim is at an amplitude limit (target maybe out of reach)


class ResonanceTracker:
    """``ResonanceTracker(settings, limits)``; ``start`` it at the speed model's set point, feed it
    speed readings with :meth:`feedback`, and call :meth:`update` every tick: it returns a new
    set point when the drive is to change (None otherwise)."""

    def __init__(self, settings: TrackerSettings, limits: DriveLimits) -> None:
        settings.check_against(limits)
        self._settings = settings
        self._limits = limits
        self._mode = TrackerMode.OFF
        self._reason = "not started"
        self._target = math.nan
        self._centre = math.nan
        self._amplitude = math.nan
        self._output = (math.nan, math.nan)  # the set point last handed out
        self._side = 1.0  # dither side of the present half-period (+1 / -1)
        self._first_side = 1.0  # side of the first half of the present cycle
        self._half_start = math.nan  # the half-period's drive is in place from here
        self._half_sum = 0.0
        self._half_count = 0
        self._half_done = False  # a reading stamped at/after the half-period's end arrived
        self._first_half: float | None = None  # mean progress of the cycle's first half
        self._error_prev = math.nan
        self._gradient = math.nan
        self._error = math.nan
        self._cycles = 0
        self._speed = math.nan
        self._last_valid_s = -math.inf  # stamp of the latest valid reading
        self._since = math.nan  # when the present mode began (staleness counts from here too)
        self._hold_s = math.nan  # when HOLD began
        self._last_now = -math.inf
        self._limited = False

    # -- configuration -----------------------------------------------------------------------------
    @property
    def settings(self) -> TrackerSettings:
        return self._settings

    @property
    def limits(self) -> DriveLimits:
        return self._limits

    def update_settings(self, settings: TrackerSettings, now_s: float) -> TrackerCommand | None:
        """New tuning. While tracking, the cycle in progress is discarded and a new one starts at
        once (its measurements belong to the old dither); returns its set point (None otherwise,
        or when holding). The centre, amplitude and trim state carry over."""
        settings.check_against(self._limits)
        self._settings = settings
        if self._mode is TrackerMode.OFF:
            return None
        # the new dither must fit around the centre (also while holding: tracking resumes there)
        centre = self._window(self._centre)
        if centre is None:
            self._off(f"the dither (+-{settings.dither_hz:g} Hz) no longer fits here")
            return None
        self._centre = min(max(self._centre, centre[0]), centre[1])
        if self._mode is TrackerMode.HOLD:
            return None
        self._restart_cycle()
        return self._emit(now_s, self._centre + self._side * settings.dither_hz)

    def update_limits(self, limits: DriveLimits, now_s: float) -> TrackerCommand | None:
        """New drive limits: the centre and amplitude are moved into them; returns the set point
        to drive now if that changed it (None otherwise). If the dither no longer fits where the
        centre is, tracking stops (OFF, with the reason)."""
        self._settings.check_against(limits)
        self._limits = limits
        if self._mode is TrackerMode.OFF:
            return None
        window = self._window(self._centre)
        if window is None:
            self._off(f"the dither (+-{self._settings.dither_hz:g} Hz) no longer fits here")
            return None
        self._centre = min(max(self._centre, window[0]), window[1])
        self._amplitude = self._clamp_amplitude(self._amplitude)
        if self._mode is TrackerMode.HOLD:
            return self._emit(now_s, self._centre)
        self._restart_cycle()
        return self._emit(now_s, self._centre + self._side * self._settings.dither_hz)

    # -- state -------------------------------------------------------------------------------------
    @property
    def mode(self) -> TrackerMode:
        return self._mode

    def status(self, now_s: float) -> TrackerStatus:
        off = self._mode is TrackerMode.OFF
        return TrackerStatus(
            mode=self._mode,
            reason=self._reason,
            centre_frequency_hz=math.nan if off else self._centre,
            amplitude_percent=math.nan if off else self._amplitude,
            measured_speed_mps=self._speed,
            gradient_per_hz=self._gradient,
            speed_error=self._error,
            cycles=self._cycles,
            feedback_age_s=max(0.0, now_s - self._last_valid_s),
            amplitude_limited=self._limited and not off,
        )

    # -- control -----------------------------------------------------------------------------------
    def start(
        self,
        now_s: float,
        frequency_hz: float,
        amplitude_percent: float,
        target_speed_mps: float,
        ready_s: float | None = None,
    ) -> TrackerCommand | None:
        """Start tracking from the drive's set point (``ready_s``: when the drive will be there,
        default ``now_s``); returns the first set point, or None (and mode OFF with the reason)
        if tracking cannot start there."""
        values = (now_s, frequency_hz, amplitude_percent, target_speed_mps)
        if not all(math.isfinite(v) for v in values):
            self._off(
                f"cannot start from frequency_hz={frequency_hz!r}, amplitude_percent="
                f"{amplitude_percent!r}, target_speed_mps={target_speed_mps!r}"
            )
            return None
        if abs(target_speed_mps) < 1e-9:
            self._off("target speed 0: no speed peak to track")
            return None
        window = self._window(frequency_hz)
        if window is None:
            self._off(
                f"the dither (+-{self._settings.dither_hz:g} Hz) does not fit in the allowed "
                f"frequency interval around {frequency_hz:g} Hz"
            )
            return None
        self._target = target_speed_mps
        self._centre = min(max(frequency_hz, window[0]), window[1])
        self._amplitude = self._clamp_amplitude(amplitude_percent)
        self._output = (frequency_hz, amplitude_percent)
        self._mode, self._reason = TrackerMode.ACTIVE, ""
        self._since = now_s
        self._last_now = now_s
        self._error_prev = math.nan
        self._gradient = self._error = math.nan
        self._cycles = 0
        self._speed = math.nan
        self._last_valid_s = -math.inf
        self._first_side = 1.0
        self._restart_cycle()
        return self._emit(
            now_s if ready_s is None else max(now_s, ready_s),
            self._centre + self._side * self._settings.dither_hz,
        )

    def stop(self, reason: str = "stopped") -> TrackerCommand | None:
        """Stop tracking; returns the centre point to hold (None if it was not tracking)."""
        if self._mode is TrackerMode.OFF:
            self._reason = reason
            return None
        command = TrackerCommand(self._centre, self._amplitude)
        self._off(reason)
        return command

    def feedback(self, t_s: float, speed_mps: float) -> bool:
        """A speed reading stamped ``t_s`` (when it was measured); False if it is ignored: not
        finite, or stamped over ``FUTURE_STAMP_TOLERANCE_S`` ahead of the tracker's clock."""
        if not (math.isfinite(t_s) and math.isfinite(speed_mps)):
            return False
        if t_s > self._last_now + FUTURE_STAMP_TOLERANCE_S:
            return False  # also every reading before the first start (which forgets them anyway)
        self._speed = speed_mps
        self._last_valid_s = max(self._last_valid_s, t_s)
        if self._mode is not TrackerMode.ACTIVE or t_s < self._half_start + self._settings.settle_s:
            return True  # before the half-period's measurement window: the previous drive's speed
        self._half_sum += speed_mps * math.copysign(1.0, self._target)
        self._half_count += 1
        if t_s >= self._half_start + self._settings.half_period_s:
            self._half_done = True
        return True

    def update(self, now_s: float) -> TrackerCommand | None:
        """Advance to ``now_s``; returns a new set point when the drive is to change."""
        if self._mode is TrackerMode.OFF:
            return None
        if now_s < self._last_now - CLOCK_JUMP_S:  # the clock jumped back: start the cycle over
            self._since = now_s
            self._last_valid_s = -math.inf
            self._restart_cycle()
            self._last_now = now_s
            if self._mode is TrackerMode.HOLD:  # keep holding the centre, on the new clock
                self._hold_s = now_s
                return self._emit(now_s, self._centre)
            return self._emit(now_s, self._centre + self._side * self._settings.dither_hz)
        self._last_now = now_s
        settings = self._settings
        age = now_s - max(self._last_valid_s, self._since)
        if self._mode is TrackerMode.HOLD:
            if self._last_valid_s <= self._hold_s:
                return None
            self._mode, self._reason = TrackerMode.ACTIVE, ""  # fresh feedback: a new cycle
            self._since = now_s
            self._restart_cycle()
            return self._emit(now_s, self._centre + self._side * settings.dither_hz)
        if age > settings.feedback_timeout_s:
            self._mode = TrackerMode.HOLD
            self._reason = (
                f"speed feedback stale: no valid reading for {age:.2f} s "
                f"(feedback_timeout_s {settings.feedback_timeout_s:g} s); holding "
                f"{self._centre:.3f} Hz, {self._amplitude:.2f} %"
            )
            self._hold_s = max(self._last_valid_s, now_s)
            return self._emit(now_s, self._centre)
        if not self._half_done or now_s < self._half_start + settings.half_period_s:
            return None
        mean = self._half_sum / self._half_count
        if self._first_half is None:  # first half done: the other side of the centre next
            self._first_half = mean
            self._side = -self._side
            self._reset_half()
            return self._emit(now_s, self._centre + self._side * settings.dither_hz)
        plus, minus = (mean, self._first_half) if self._side > 0 else (self._first_half, mean)
        self._finish_cycle(plus, minus)
        self._first_side = -self._first_side  # +- then -+: a linear drift cancels over two
        self._restart_cycle()
        return self._emit(now_s, self._centre + self._side * settings.dither_hz)

    # -- internals ---------------------------------------------------------------------------------
    def _finish_cycle(self, plus: float, minus: float) -> None:
        settings = self._settings
        target = abs(self._target)
        self._gradient = (plus - minus) / (2.0 * settings.dither_hz * target)
        step = min(
            max(settings.gain_hz2 * self._gradient, -settings.max_step_hz), settings.max_step_hz
        )
        window = self._window(self._centre)
        assert window is not None, "the centre always lies where the dither fits"
        self._centre = min(max(self._centre + step, window[0]), window[1])
        error = (target - 0.5 * (plus + minus)) / target
        change = settings.amplitude_ki_percent * error
        if math.isfinite(self._error_prev):
            change += settings.amplitude_kp_percent * (error - self._error_prev)
        limit = settings.max_amplitude_step_percent
        wanted = self._amplitude + min(max(change, -limit), limit)
        self._amplitude = self._clamp_amplitude(wanted)
        self._limited = self._amplitude != wanted
        self._error_prev = error
        self._error = error
        self._cycles += 1

    def _restart_cycle(self) -> None:
        self._side = self._first_side
        self._first_half = None
        self._reset_half()

    def _reset_half(self) -> None:
        self._half_start = math.inf  # set by _emit once the drive's ramp is known
        self._half_sum = 0.0
        self._half_count = 0
        self._half_done = False

    def _emit(self, now_s: float, frequency_hz: float) -> TrackerCommand:
        """Hand out a set point; the half-period starts when the drive's ramp to it is done."""
        amplitude = self._amplitude
        previous_f, previous_a = self._output
        ramp = self._limits.minimum_ramp_time_s(previous_f, previous_a, frequency_hz, amplitude)
        self._output = (frequency_hz, amplitude)
        self._half_start = now_s + ramp
        return TrackerCommand(frequency_hz, amplitude)

    def _window(self, frequency_hz: float) -> tuple[float, float] | None:
        """The centre frequencies usable around ``frequency_hz``: its allowed interval (the wider
        one at a band edge) shrunk by the dither; None if the dither does not fit there."""
        dither = self._settings.dither_hz
        best: tuple[float, float] | None = None
        for low, high in self._limits.allowed_intervals():
            if not low - 1e-9 <= frequency_hz <= high + 1e-9 or high - low < 2.0 * dither:
                continue
            if best is None or high - low > best[1] - best[0] + 2.0 * dither:
                best = (low + dither, high - dither)
        return best

    def _clamp_amplitude(self, amplitude_percent: float) -> float:
        top = self._limits.max_amplitude_percent
        return min(max(amplitude_percent, AMPLITUDE_FLOOR_FRACTION * top), top)

    def _off(self, reason: str) -> None:
        self._mode = TrackerMode.OFF
        self._reason = reason
        self._limited = False
