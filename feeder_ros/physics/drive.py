"""Drive force schedule ``F(t) = A(t)*sin(phase(t))`` of the feeder's exciter.

The drive is piecewise sinusoidal: on each segment ``k`` (from ``t_k`` to ``t_{k+1}``) frequency
``f_k`` and amplitude ``A_k`` are constant and ``F(t) = A_k*sin(phi_k + 2*pi*f_k*(t - t_k))``. The
phase is continuous across every change (``phi_{k+1} = phi_k + 2*pi*f_k*(t_{k+1} - t_k)``, kept
modulo 2*pi); the amplitude and the frequency jump. ``phi_0 = 0`` at ``t = 0``, so the default drive
is ``A*sin(2*pi*f*t)``.

A change with ``ramp_s > 0`` is applied as a staircase: the ramp is cut into
``ceil(ramp_s/ramp_step_s)`` equal steps, at most ``MAX_RAMP_STEPS`` (a longer ramp takes longer
steps: its segments are built in Python and handed to the solver, so their count is bounded);
on step ``j`` (of ``n``) the frequency and amplitude are the linear interpolation between the old
and the new values at the step's end fraction ``(j+1)/n``,
so the target is reached exactly at the end of the ramp. The simulator integrates this staircase
exactly: the drive actually applied is the staircase, not a smooth ramp (with the default 1 ms step
the difference is far below any physical uncertainty of a real exciter).

Changes are absolute in time. A new change (``DriveSchedule.with_change``) supersedes every change
that would have taken effect after its own start time: it starts from the values the old schedule
has at that instant (mid-ramp included).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.parameters import is_number

__all__ = [
    "DEFAULT_RAMP_STEP_S",
    "MAX_RAMP_STEPS",
    "MAX_TIME_S",
    "DriveChange",
    "DriveError",
    "DriveSchedule",
    "DriveSegments",
]

DEFAULT_RAMP_STEP_S = 1e-3
#: the most steps one ramp is cut into (10 s at the default step; a longer ramp, or a shorter
#: ``ramp_step_s``, takes longer steps)
MAX_RAMP_STEPS = 10_000
#: the latest change time and the longest ramp [s] (some 30 years: beyond, the phase's
#: arithmetic overflows)
MAX_TIME_S = 1e9
TWO_PI = 2.0 * math.pi


class DriveError(ValueError):
    """A drive value the model cannot accept; the message names the value."""


def _check(name: str, value: float, allow_zero: bool, at_most: float = math.inf) -> float:
    if not is_number(value):
        raise DriveError(f"{name}={value!r} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise DriveError(f"{name}={value!r} is not finite")
    if number < 0.0 or (number == 0.0 and not allow_zero):
        relation = ">=" if allow_zero else ">"
        raise DriveError(f"{name}={value!r} must be {relation} 0")
    if number > at_most:
        raise DriveError(f"{name}={value!r} must be <= {at_most:g}")
    return number


@dataclass(frozen=True)
class DriveChange:
    """From ``time_s`` on, drive at ``frequency_hz``/``amplitude_n``, reached linearly over
    ``ramp_s``."""

    time_s: float
    frequency_hz: float
    amplitude_n: float
    ramp_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_s", _check("time_s", self.time_s, True, MAX_TIME_S))
        object.__setattr__(self, "frequency_hz", _check("frequency_hz", self.frequency_hz, False))
        object.__setattr__(self, "amplitude_n", _check("amplitude_n", self.amplitude_n, True))
        object.__setattr__(self, "ramp_s", _check("ramp_s", self.ramp_s, True, MAX_TIME_S))


@dataclass(frozen=True)
class DriveSegments:
    """The applied drive as arrays, one entry per constant segment (what the solver consumes).

    ``start_s[k]`` (``start_s[0]`` is the schedule's start, 0 unless older changes were
    forgotten), angular frequency ``omega_rad_s[k]`` (``2*pi*frequency_hz[k]``), amplitude
    ``amplitude_n[k]``, phase ``phase_rad[k]`` at ``start_s[k]``, and ``logged[k]``: 1 if segment
    ``k`` begins a user change (recorded as a DRIVE_CHANGE event), 0 for the inner steps of a ramp
    and for segment 0.
    """

    start_s: npt.NDArray[np.float64]
    omega_rad_s: npt.NDArray[np.float64]
    amplitude_n: npt.NDArray[np.float64]
    phase_rad: npt.NDArray[np.float64]
    logged: npt.NDArray[np.int8]
    frequency_hz: npt.NDArray[np.float64]

    def index_at(self, time_s: float) -> int:
        """Index of the segment in force at ``time_s`` (segments are half-open ``[start,
        next)``)."""
        if self.start_s.shape[0] == 1:
            return 0  # a constant drive (the common case: no search)
        return max(int(np.searchsorted(self.start_s, time_s, side="right")) - 1, 0)

    def force(self, time_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The applied force ``F(t)`` at the given times (vectorised)."""
        t = np.asarray(time_s, dtype=np.float64)
        k = np.clip(np.searchsorted(self.start_s, t, side="right") - 1, 0, None)
        return np.asarray(
            self.amplitude_n[k]
            * np.sin(self.phase_rad[k] + self.omega_rad_s[k] * (t - self.start_s[k])),
            dtype=np.float64,
        )


@dataclass(frozen=True)
class DriveSchedule:
    """Initial frequency/amplitude (at ``start_s``, 0 by default) and a time-ordered tuple of
    :class:`DriveChange`.

    ``start_s``/``start_phase_rad``: where the schedule starts and the phase there (0, 0 for a
    new schedule; later for one that forgot its older changes, :meth:`forget_before`). Before
    ``start_s`` it describes nothing (queries there get the initial values)."""

    frequency_hz: float
    amplitude_n: float
    changes: tuple[DriveChange, ...] = ()
    ramp_step_s: float = DEFAULT_RAMP_STEP_S
    start_s: float = 0.0
    start_phase_rad: float = 0.0
    _segments: DriveSegments | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequency_hz", _check("frequency_hz", self.frequency_hz, False))
        object.__setattr__(self, "amplitude_n", _check("amplitude_n", self.amplitude_n, True))
        object.__setattr__(self, "ramp_step_s", _check("ramp_step_s", self.ramp_step_s, False))
        changes = tuple(self.changes)
        for change in changes:
            if not isinstance(change, DriveChange):
                raise DriveError(f"changes must hold DriveChange values, got {change!r}")
        times = [change.time_s for change in changes]
        if times != sorted(times):
            raise DriveError(f"drive changes must be in time order, got times {times}")
        object.__setattr__(self, "start_s", _check("start_s", self.start_s, True))
        phase = self.start_phase_rad
        if not (isinstance(phase, int | float) and 0.0 <= phase < TWO_PI):
            raise DriveError(f"start_phase_rad={phase!r} must be in [0, 2*pi)")
        if times and times[0] < self.start_s:
            raise DriveError(f"a change at {times[0]!r} s is before start_s={self.start_s!r}")
        object.__setattr__(self, "changes", changes)

    @classmethod
    def constant(cls, frequency_hz: float, amplitude_n: float) -> DriveSchedule:
        return cls(frequency_hz, amplitude_n)

    def with_change(self, change: DriveChange) -> DriveSchedule:
        """This schedule with ``change`` added; changes after ``change.time_s`` are dropped.

        The new change starts from the values this schedule has at ``change.time_s``: a change
        scheduled at or before that instant, or a ramp still running, is cut there.
        """
        f0, a0 = self.values_at(change.time_s)
        kept = [c for c in self.changes if c.time_s < change.time_s]
        # A ramp still running at change.time_s is frozen at its current staircase value.
        if kept and kept[-1].time_s + kept[-1].ramp_s > change.time_s:
            kept.append(DriveChange(change.time_s, f0, a0, 0.0))
        return DriveSchedule(
            self.frequency_hz,
            self.amplitude_n,
            (*kept, change),
            self.ramp_step_s,
            self.start_s,
            self.start_phase_rad,
        )

    def forget_before(self, time_s: float) -> DriveSchedule:
        """The same drive from ``time_s`` on, without the changes that only shaped it before.

        The new schedule starts on the segment before the last change that took effect at or
        before ``time_s``, with that segment's values and phase; that change and all later ones
        are kept. Its segments from there on are the same numbers, bit for bit. A live
        simulator calls this so that its schedule, rebuilt on every command, does not grow
        with the length of the run. Returns ``self`` when there is nothing to forget.
        """
        seg = self.segments()
        now = int(np.searchsorted(seg.start_s, time_s, side="right")) - 1  # segment in force
        opened = np.flatnonzero(seg.logged[1 : now + 1])  # segments 1..now that begin a change
        if opened.size == 0:
            return self
        first = int(opened[-1]) + 1  # the last change in force opens segment `first`
        base = first - 1
        opened_at = float(seg.start_s[first])
        kept = tuple(change for change in self.changes if change.time_s >= opened_at)
        if len(kept) == len(self.changes):
            return self
        return DriveSchedule(
            float(seg.frequency_hz[base]),
            float(seg.amplitude_n[base]),
            kept,
            self.ramp_step_s,
            float(seg.start_s[base]),
            float(seg.phase_rad[base]),
        )

    def values_at(self, time_s: float) -> tuple[float, float]:
        """(frequency_hz, amplitude_n) of the applied (staircase) drive at ``time_s``."""
        seg = self.segments()
        k = seg.index_at(time_s)
        return float(seg.omega_rad_s[k] / TWO_PI), float(seg.amplitude_n[k])

    def force(self, time_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The applied force ``F(t)`` (vectorised)."""
        return self.segments().force(time_s)

    def segments(self) -> DriveSegments:
        """The applied drive as constant segments with continuous phase (cached)."""
        if self._segments is None:
            object.__setattr__(self, "_segments", self._build())
        assert self._segments is not None
        return self._segments

    def _build(self) -> DriveSegments:
        starts = [self.start_s]
        freqs = [self.frequency_hz]
        amps = [self.amplitude_n]
        logged = [0]

        def add(time_s: float, freq: float, amp: float, log: int) -> None:
            if time_s <= starts[-1]:  # only at start_s: replaces the initial values
                freqs[-1], amps[-1] = freq, amp
                return
            starts.append(time_s)
            freqs.append(freq)
            amps.append(amp)
            logged.append(log)

        for change in self.changes:
            # A change supersedes whatever was scheduled from its start time on.
            while len(starts) > 1 and starts[-1] >= change.time_s:
                starts.pop()
                freqs.pop()
                amps.pop()
                logged.pop()
            f_old, a_old = freqs[-1], amps[-1]
            if change.ramp_s <= 0.0:
                add(change.time_s, change.frequency_hz, change.amplitude_n, 1)
                continue
            ratio = change.ramp_s / self.ramp_step_s  # inf for an extreme pair: capped
            n = max(1, math.ceil(ratio - 1e-9)) if ratio < MAX_RAMP_STEPS else MAX_RAMP_STEPS
            for j in range(n):
                frac = (j + 1) / n
                add(
                    change.time_s + change.ramp_s * j / n,
                    f_old + (change.frequency_hz - f_old) * frac,
                    a_old + (change.amplitude_n - a_old) * frac,
                    1 if j == 0 else 0,
                )
        start = np.asarray(starts, dtype=np.float64)
        omega = TWO_PI * np.asarray(freqs, dtype=np.float64)
        phase = np.zeros_like(start)
        phase[0] = self.start_phase_rad
        for k in range(1, len(start)):
            phase[k] = math.fmod(phase[k - 1] + omega[k - 1] * (start[k] - start[k - 1]), TWO_PI)
        return DriveSegments(
            start,
            omega,
            np.asarray(amps, dtype=np.float64),
            phase,
            np.asarray(logged, np.int8),
            np.asarray(freqs, dtype=np.float64),
        )
