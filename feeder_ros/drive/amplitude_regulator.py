"""Vibration-amplitude regulation on the carrier's accelerometer (ROS-free, clock-free).

Industrial feeder controllers hold the carrier's vibration amplitude when load, spring stiffness
or mains voltage change: this is that inner loop. The caller supplies the time.

**Measuring** (:class:`LineAmplitude`): the amplitude of the accelerometer's line at the drive
frequency ``f``, by least squares over ``window_periods`` whole drive periods of an offset (bias,
a tilt's share of g), the line and its :data:`HARMONICS` first harmonics (a bilinear carrier's
motion is no sinusoid), so neither leaks into the line. ``residual_mps2`` is the rms of what
offset and line leave (harmonics, noise, the rest). Windows follow each other; a new frequency or
a clock stepping back starts a new one. Non-finite samples are dropped and counted (``dropped``).

**The plant.** ``M x'' + c x' + K(x) x = F sin(2 pi f t)`` with piecewise-linear springs switching
at ``x = 0`` is *positively homogeneous*: scaling ``F`` by ``s > 0`` scales the steady motion by
``s``. At a given frequency the line is ``y = g(f) * u`` for the drive amplitude ``u`` [%], however
nonlinear the springs: a multiplicative model with one unknown, the gain ``g`` (load, stiffness
and mains voltage move it).

**The law** (:class:`AmplitudeRegulator`). A usable window gives ``g = y / u`` (``u``: the %
applied, from the caller) and the command steps toward the set point ``r``:
``u+ = u + gain * (r / g - u)``, at most ``max_step_percent`` points, clamped to
``[0, max_amplitude_percent]``. That is ``u+ = u * (1 + gain * (r - y) / y)``: a change
proportional to the error, an integral-type loop (no steady-state error whatever ``g``), its loop
gain normalised by the measured ``g``: on the multiplicative model each step shrinks the error by
``1 - gain`` at any load and frequency.

* A window counts when the applied % at its end equals (:data:`STEADY_TOLERANCE`) the one passed
  with the adjacent previous window at the same frequency: the drive then stood still over it.
  The window of a step or a ramp is skipped (the command held), which also lets the carrier's
  transient decay (``2 M / c`` = 0.1 s for the realistic preset).
* Anti-windup: the command comes from the applied % and the measured gain, not from a sum of
  errors: it never passes the limit (``limited``, with the reason), and leaves it in the first
  window in which the set point is reachable again.
* Set points beyond ``g(f) * max_amplitude_percent`` are refused once ``g`` is known; with no gain
  and the drive at 0 %, the regulator probes with one ``max_step_percent`` step. No measurement
  for ``stale_after_s``: hold the present amplitude, reported stale.

**Sub-harmonics.** A bilinear carrier readily settles into orbits of 2 or 3 drive periods (the
realistic preset: at 20 Hz a 10 Hz line 0.8 times the 20 Hz one; at 30 Hz lines at 10 and 20 Hz).
Such an orbit scales with ``F`` too, but its line is measured right only over whole orbits: hence
``window_periods = 6``. With 8 the 30 Hz line scattered by 3-5 % from window to window.

**What breaks the model**, and the one-step convergence (the loop still integrates, its gain off by
``(dy/du) / (y/u)``): non-linear damping (air, squeeze film), Coulomb friction in the springs or
two-way coupling of slipping parts (forces that do not scale with ``F``), a spring switch away from
``x = 0`` (preload), a saturating accelerometer; motion not periodic over the window (longer
orbits, chaos), a jump between coexisting orbits (taken as a new gain). Those show in the
residual: above :data:`RESIDUAL_WARNING` times the line it is reported in ``reason`` (the loop
still acts). This carrier's residual is normally 0.25-0.75 of its line (harmonics, sub-harmonics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.parameters import is_number

__all__ = [
    "AmplitudeError",
    "AmplitudeMeasurement",
    "AmplitudeRegulator",
    "AmplitudeSettings",
    "LineAmplitude",
    "RegulatorOutput",
]

#: harmonics of the drive frequency fitted beside the line (so that they do not leak into it)
HARMONICS = 5
#: a window needs this many samples per drive period on average
MIN_SAMPLES_PER_PERIOD = 4
#: relative change of the applied % between two windows' ends that still counts as standing still
STEADY_TOLERANCE = 0.005
#: a gain measured within this relative distance of a frequency stands for it
FREQUENCY_TOLERANCE = 0.01
#: residual / line above which the line may not stand for the motion (a warning reason): the line
#: then carries less than a third of the signal's power
RESIDUAL_WARNING = 1.0


class AmplitudeError(ValueError):
    """A setting or an input the regulator cannot use; the message names the value."""


@dataclass(frozen=True)
class AmplitudeSettings:
    window_periods: int = 6  #: measure over this many drive periods (>= 2; 6: 2- and 3-orbits)
    gain: float = 0.7  #: fraction of the correction applied per window, (0, 1]
    max_step_percent: float = 10.0  #: largest amplitude change per window [% points] (> 0)
    stale_after_s: float = 1.0  #: no measurement this long: hold, report stale (> 0)

    def __post_init__(self) -> None:
        for item in fields(self):
            value = getattr(self, item.name)
            if not is_number(value) or not math.isfinite(value):
                raise AmplitudeError(f"amplitude {item.name}={value!r} is not a finite number")
        if self.window_periods != int(self.window_periods) or self.window_periods < 2:
            raise AmplitudeError(f"window_periods={self.window_periods!r} must be an integer >= 2")
        object.__setattr__(self, "window_periods", int(self.window_periods))
        if not 0.0 < self.gain <= 1.0:
            raise AmplitudeError(f"amplitude gain={self.gain!r} must be in (0, 1]")
        for name in ("max_step_percent", "stale_after_s"):
            if getattr(self, name) <= 0.0:
                raise AmplitudeError(f"{name}={getattr(self, name)!r} must be > 0")

    def window_s(self, frequency_hz: float) -> float:
        return self.window_periods / frequency_hz


@dataclass(frozen=True)
class AmplitudeMeasurement:
    t_s: float  #: end of the window
    frequency_hz: float  #: the drive frequency it was measured at
    amplitude_mps2: float  #: amplitude of the accelerometer's drive-frequency line [m/s^2]
    residual_mps2: float  #: rms of what the line does not explain (harmonics, noise) [m/s^2]


def _same_frequency(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)


class LineAmplitude:
    """Amplitude of the drive-frequency line of a sampled acceleration (least squares of offset,
    line and harmonics at the known drive frequency over whole drive periods)."""

    def __init__(self, settings: AmplitudeSettings) -> None:
        self.settings = settings
        self.dropped = 0  #: non-finite samples dropped (since construction)
        self.discarded = 0  #: windows with too few samples to fit (since construction)
        self.reset()

    def reset(self) -> None:
        """Forget the partial window (the counters stay)."""
        self._frequency = math.nan
        self._start = math.nan
        self._t: npt.NDArray[np.float64] = np.zeros(0)
        self._a: npt.NDArray[np.float64] = np.zeros(0)

    def add(
        self, t_s: npt.ArrayLike, accel_mps2: npt.ArrayLike, frequency_hz: float
    ) -> list[AmplitudeMeasurement]:
        """Add a batch of samples (sorted times) taken at drive frequency ``frequency_hz``;
        returns the measurements of the windows this batch completes."""
        if not (is_number(frequency_hz) and math.isfinite(frequency_hz) and frequency_hz > 0.0):
            raise AmplitudeError(f"frequency_hz={frequency_hz!r} must be finite and > 0")
        t = np.asarray(t_s, dtype=np.float64).ravel()
        a = np.asarray(accel_mps2, dtype=np.float64).ravel()
        if t.shape != a.shape:
            raise AmplitudeError(f"{t.size} sample times for {a.size} accelerations")
        finite = np.isfinite(t) & np.isfinite(a)
        if not finite.all():
            self.dropped += int(t.size - np.count_nonzero(finite))
            t, a = t[finite], a[finite]
        if t.size > 1 and not np.all(np.diff(t) > 0.0):
            raise AmplitudeError("sample times within a batch must increase")
        stepped_back = bool(self._t.size and t.size and t[0] <= self._t[-1])
        if stepped_back or not _same_frequency(frequency_hz, self._frequency):
            self.reset()  # a new window
            self._frequency = float(frequency_hz)
        if t.size == 0:
            return []
        if math.isnan(self._start):
            self._start = float(t[0])
        self._t = np.concatenate((self._t, t))
        self._a = np.concatenate((self._a, a))
        return self._complete_windows()

    def _complete_windows(self) -> list[AmplitudeMeasurement]:
        out: list[AmplitudeMeasurement] = []
        length = self.settings.window_s(self._frequency)
        while self._t.size and self._t[-1] >= self._start + length:
            end = self._start + length
            n = int(np.searchsorted(self._t, end, side="left"))
            measurement = self._fit(self._t[:n], self._a[:n], end)
            if measurement is None:
                self.discarded += 1
            else:
                out.append(measurement)
            self._t, self._a = self._t[n:], self._a[n:]
            # a gap (a sensor dropout) longer than a window: the next window starts at the data
            self._start = end if self._t[0] < end + length else float(self._t[0])
        return out

    def _fit(
        self, t: npt.NDArray[np.float64], a: npt.NDArray[np.float64], end: float
    ) -> AmplitudeMeasurement | None:
        periods = self.settings.window_periods
        per_period = t.size / periods
        harmonics = min(HARMONICS, math.ceil(per_period / 2.0) - 1)
        if per_period < MIN_SAMPLES_PER_PERIOD or t.size < 3 * (2 * harmonics + 1):
            return None
        phase = 2.0 * math.pi * self._frequency * (t - self._start)
        k = np.arange(1, harmonics + 1)
        columns = [np.ones_like(t), np.cos(np.outer(phase, k)).T, np.sin(np.outer(phase, k)).T]
        design = np.vstack([np.atleast_2d(c) for c in columns]).T
        coef = np.linalg.lstsq(design, a, rcond=None)[0]
        cos1, sin1 = coef[1], coef[1 + harmonics]
        line = coef[0] + cos1 * np.cos(phase) + sin1 * np.sin(phase)
        residual = float(np.sqrt(np.mean((a - line) ** 2)))
        return AmplitudeMeasurement(end, self._frequency, float(math.hypot(cos1, sin1)), residual)


@dataclass(frozen=True)
class RegulatorOutput:
    amplitude_percent: float  #: the drive amplitude to command
    limited: bool  #: at the drive's limit (anti-windup: no accumulation beyond it)
    reason: str  #: '' or why the output is not simply the regulated one (limit, warning, stale)
    steady: bool = False  #: the window's drive stood still: its gain was measured


class AmplitudeRegulator:
    """See the module docstring. ``last_note`` says what the latest update did."""

    def __init__(self, settings: AmplitudeSettings, max_amplitude_percent: float) -> None:
        if not (is_number(max_amplitude_percent) and 0.0 < max_amplitude_percent <= 100.0):
            raise AmplitudeError(
                f"max_amplitude_percent={max_amplitude_percent!r} must be in (0, 100]"
            )
        self.settings = settings
        self.max_amplitude_percent = float(max_amplitude_percent)
        self.reset()

    def reset(self) -> None:
        self._set_point = math.nan
        self._gain = math.nan  # measured m/s^2 per %
        self._gain_hz = math.nan
        self._previous: AmplitudeMeasurement | None = None
        self._previous_applied = math.nan
        self._output: RegulatorOutput | None = None
        self._limit_reason = ""
        self.last_note = "no measurement yet"

    @property
    def set_point_mps2(self) -> float:
        return self._set_point

    def set_point(self, amplitude_mps2: float, reachable_max_mps2: float | None) -> str:
        """Accept a set point (''), or refuse it naming the value; a refusal changes nothing."""
        value = amplitude_mps2
        if not (is_number(value) and math.isfinite(value)):
            return f"amplitude set point {value!r} m/s^2 is not a finite number"
        if value <= 0.0:
            return f"amplitude set point {value:g} m/s^2 must be > 0"
        reach = reachable_max_mps2
        if reach is not None and math.isfinite(reach) and value > reach:
            at = f" at {self._gain_hz:g} Hz" if math.isfinite(self._gain_hz) else ""
            return (
                f"amplitude set point {value:g} m/s^2 beyond the drive's reach: "
                f"0 .. {reach:.4g} m/s^2{at}"
            )
        self._set_point = float(value)
        return ""

    def gain_at(self, frequency_hz: float) -> float | None:
        """The measured m/s^2 per % at (about) this frequency, None if none was measured."""
        if abs(frequency_hz - self._gain_hz) <= FREQUENCY_TOLERANCE * self._gain_hz:
            return self._gain
        return None

    def reachable_max_mps2(self, frequency_hz: float) -> float | None:
        gain = self.gain_at(frequency_hz)
        return None if gain is None else gain * self.max_amplitude_percent

    def stale(self, t_s: float) -> bool:
        last = self._previous
        return last is None or not t_s - last.t_s <= self.settings.stale_after_s

    def update(self, measurement: AmplitudeMeasurement, applied_percent: float) -> RegulatorOutput:
        """The command after a window's measurement; ``applied_percent``: the drive's amplitude
        at the window's end (what it applied over the window, if it stood still)."""
        if not (is_number(applied_percent) and math.isfinite(applied_percent)):
            raise AmplitudeError(f"applied_percent={applied_percent!r} is not finite")
        cfg, top, m = self.settings, self.max_amplitude_percent, measurement
        applied = min(max(float(applied_percent), 0.0), top)
        previous, previous_applied = self._previous, self._previous_applied
        self._previous, self._previous_applied = m, float(applied_percent)
        steady = (
            previous is not None
            and _same_frequency(m.frequency_hz, previous.frequency_hz)
            and 0.0 < m.t_s - previous.t_s <= 1.5 * cfg.window_s(m.frequency_hz)
            and math.isclose(applied_percent, previous_applied, rel_tol=STEADY_TOLERANCE)
            and math.isfinite(m.amplitude_mps2)
        )
        if steady and applied > 0.0 and m.amplitude_mps2 > 0.0:
            self._gain, self._gain_hz = m.amplitude_mps2 / applied, m.frequency_hz
        warning = ""
        if not m.residual_mps2 <= RESIDUAL_WARNING * m.amplitude_mps2:
            warning = (
                f"residual {m.residual_mps2:.3g} m/s^2 exceeds {RESIDUAL_WARNING:g} x the "
                f"{m.amplitude_mps2:.3g} m/s^2 line at {m.frequency_hz:g} Hz: sub-harmonics, "
                "chaos or noise? The line may not stand for the motion"
            )
        gain = self.gain_at(m.frequency_hz)
        held = self._output.amplitude_percent if self._output is not None else applied
        limited = False
        if math.isnan(self._set_point):
            command, self.last_note = applied, "no amplitude set point: holding"
        elif gain is None and applied == 0.0:
            command = min(cfg.max_step_percent, top)
            self.last_note = f"drive at 0 %, gain unknown: probing with {command:g} %"
        elif gain is None or not steady:
            command, self.last_note = held, "no steady window at this amplitude yet: holding"
            limited = self._output is not None and self._output.limited and command >= top
        else:
            needed = self._set_point / gain
            step = cfg.gain * (needed - applied)
            step = max(-cfg.max_step_percent, min(cfg.max_step_percent, step))
            command = min(max(applied + step, 0.0), top)
            limited = needed > top and command >= top
            self.last_note = (
                f"{m.amplitude_mps2:.4g} m/s^2 at {applied:.4g} %: stepped to {command:.4g} %"
            )
            self._limit_reason = (
                f"set point {self._set_point:g} m/s^2 needs {needed:.4g} % > max {top:g} %: "
                f"holding {top:g} %"
            )
        if limited:
            warning = "; ".join(filter(None, (self._limit_reason, warning)))
        self._output = RegulatorOutput(command, limited, warning, bool(steady))
        return self._output

    def output(self, t_s: float, current_percent: float) -> RegulatorOutput:
        """Between measurements: the latest command; stale: hold ``current_percent``."""
        current = min(max(current_percent, 0.0), self.max_amplitude_percent)
        last = self._previous
        if last is None:
            return RegulatorOutput(current, False, f"no measurement yet: holding {current:g} %")
        if self.stale(t_s):
            return RegulatorOutput(
                current,
                False,
                f"no measurement for {t_s - last.t_s:.3g} s (> {self.settings.stale_after_s:g} "
                f"s): stale, holding {current:g} %",
            )
        assert self._output is not None  # set with _previous
        return self._output
