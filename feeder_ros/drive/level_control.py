"""Track level control, ROS-free: pause the feeder while its track is full, as industrial feeder
controllers (REOVIB MFS 268/368) do with part-present sensors (light barriers) along the track.

Parts queue back from the track's end and a sensor upstream sees the queue reach it. The node gives
:class:`LevelControl` the sensor edges (``edge``) and asks every tick whether feeding is allowed
(``update``), all times from one clock (the node clock, in seconds). Modes:

* ``one_sensor``: covered continuously for ``off_delay_s`` -> track full, paused; then free
  continuously for ``on_delay_s`` -> resume. A passing part covers the sensor for well under the
  off delay, so a moving stream of parts never pauses the feeder.
* ``two_sensors`` (min/max band): the full (max) sensor covered for ``off_delay_s`` pauses; feeding
  resumes only once the low (min) sensor has been free for ``on_delay_s`` and the full one is not
  covered, so the track drains from max to min before the feeder switches on (hysteresis). While
  feeding, a covered low sensor changes nothing.
* ``off``: feeding always allowed, never a fault.

Sensor time-out: in FEEDING while the drive outputs vibration (``update``'s ``feeding``), no change
on any watched sensor for ``sensor_timeout_s`` (empty hopper, jam, dead sensor) latches FAULT until
``reset``; counted from the latest of the last change, the update at which feeding (re)started and
the last reset. Pause time never counts: a covered sensor is the normal state of a full track.

A sensor that changes and changes back at one instant (touching parts: one leaves as the next
arrives, in either order) never changed, as a light barrier would see it. Decided here: a sensor
not seen yet is unknown (None) and counts as free (the feeder starts by
feeding); sensors report changes only, so the node seeds each known state with ``edge``. No timer
counts from before the first ``update`` (or the last ``reset``/clock restart). An edge repeating
the known state changes nothing (no timer restarts, no time-out activity). An edge stamped before
the newest one seen on its sensor is stale and dropped (``stale_edges``): applied in arrival order,
the late rising edge of a part already gone would leave the sensor covered for good. Time never
runs back: an ``update`` up to ``CLOCK_JUMP_S`` before the last counts as the last; a larger step
back (sim time restarted) restarts every timer, keeping sensor states and a fault; an edge stamped
over ``CLOCK_JUMP_S`` after the last update (the old clock, in flight) counts from that update.
``reset`` clears a fault (-> FEEDING), keeps a pause, and restarts the delay timers and time-out.
"""

from __future__ import annotations

import enum
import math
import numbers
from dataclasses import dataclass

__all__ = [
    "LevelControl",
    "LevelDecision",
    "LevelError",
    "LevelMode",
    "LevelSettings",
    "LevelState",
]

CLOCK_JUMP_S = 1.0  # an update this much before the last one means the clock restarted
_SLACK_S = 1e-9  # float rounding: 0.7 - 0.4 s counts as the 0.3 s it is


class LevelError(ValueError):
    """Bad level-control settings or a non-finite time; the message names the value."""


class LevelMode(enum.StrEnum):  # a str and an Enum: LevelMode.OFF == "off"
    OFF = "off"
    ONE_SENSOR = "one_sensor"
    TWO_SENSORS = "two_sensors"


class LevelState(enum.IntEnum):
    OFF = 0  # level control off
    FEEDING = 1  # track not full: feeding allowed
    FULL = 2  # track full: feeding paused
    FAULT = 3  # sensor time-out latched until reset()


def _seconds(value: float) -> str:
    return f"{value:.1f}" if value >= 1.0 else f"{value:.3g}"


def _finite(name: str, value: float) -> float:
    if not (isinstance(value, numbers.Real) and math.isfinite(value)):
        raise LevelError(f"{name}={value!r} must be finite")
    return value


def _mode(value: object) -> LevelMode:
    if isinstance(value, LevelMode):
        return value
    if isinstance(value, str):
        for mode in LevelMode:
            if mode.value == value.strip().lower():
                return mode
    valid = ", ".join(repr(mode.value) for mode in LevelMode)
    raise LevelError(f"level.mode={value!r} is not a level mode (valid: {valid})")


@dataclass(frozen=True)
class LevelSettings:
    """Validated settings (the node's ``level.*`` parameters); a bad one raises LevelError."""

    mode: LevelMode = LevelMode.OFF
    full_sensor_index: int = 1  # one_sensor: the sensor; two_sensors: the max (full) sensor
    low_sensor_index: int = 0  # two_sensors only: the min (low) sensor
    off_delay_s: float = 1.0  # covered this long before the feeder pauses
    on_delay_s: float = 1.0  # free this long before the feeder resumes
    sensor_timeout_s: float = 30.0  # no change this long while feeding -> fault; 0: none

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", _mode(self.mode))
        for name in ("full_sensor_index", "low_sensor_index"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
                raise LevelError(f"level.{name}={value!r} must be an integer >= 0")
            object.__setattr__(self, name, int(value))
        for name in ("off_delay_s", "on_delay_s", "sensor_timeout_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise LevelError(f"level.{name}={value!r} must be a number of seconds")
            seconds = float(value)
            if not (math.isfinite(seconds) and seconds >= 0.0):
                raise LevelError(f"level.{name}={value!r} must be finite and >= 0")
            object.__setattr__(self, name, seconds)
        if self.mode is LevelMode.TWO_SENSORS and self.low_sensor_index == self.full_sensor_index:
            raise LevelError(
                f"level.low_sensor_index={self.low_sensor_index} equals level.full_sensor_index:"
                " two_sensors mode needs two different sensors"
            )

    @classmethod
    def from_values(
        cls,
        mode: str,
        full_sensor_index: int,
        low_sensor_index: int,
        off_delay_s: float,
        on_delay_s: float,
        sensor_timeout_s: float,
    ) -> LevelSettings:
        """From ROS parameter values; ``mode`` by its value ("one_sensor", case ignored)."""
        indices = (full_sensor_index, low_sensor_index)
        return cls(_mode(mode), *indices, off_delay_s, on_delay_s, sensor_timeout_s)

    @property
    def roles(self) -> tuple[tuple[str, int], ...]:
        """The watched sensors as (role, index), in ``LevelDecision.sensors``' order:
        () when off, (("full", i),) for one sensor, (("low", i), ("full", j)) for two."""
        if self.mode is LevelMode.ONE_SENSOR:
            return (("full", self.full_sensor_index),)
        if self.mode is LevelMode.TWO_SENSORS:
            return (("low", self.low_sensor_index), ("full", self.full_sensor_index))
        return ()

    @property
    def watched(self) -> tuple[int, ...]:
        """The watched sensor indices, in ``LevelDecision.sensors``' order."""
        return tuple(index for _, index in self.roles)

    def check_sensor_count(self, sensor_count: int) -> None:
        """LevelError if a sensor this mode uses is not one of the feeder's ``sensor_count``."""
        for role, index in self.roles:
            if 0 <= index < sensor_count:
                continue
            name = f"level.{role}_sensor_index={index}"
            if sensor_count <= 0:
                raise LevelError(f"{name}: the feeder has no part-present sensors")
            sensors = "sensor" if sensor_count == 1 else "sensors"
            raise LevelError(
                f"{name}: the feeder has {sensor_count} part-present {sensors} "
                f"(0..{sensor_count - 1})"
            )


@dataclass(frozen=True)
class LevelDecision:
    """``sensors``: the watched ones in ``settings.watched`` order, () / (full,) / (low, full);
    True covered, False free, None not seen yet."""

    feed_allowed: bool  # True in OFF and FEEDING
    state: LevelState
    reason: str  # why feeding is paused or faulted; "" when allowed
    fault: str  # the latched time-out reason in FAULT, else ""
    sensors: tuple[bool | None, ...]


@dataclass
class _Sensor:
    index: int
    covered: bool | None = None  # None: no edge seen yet (counts as free)
    since_s: float = -math.inf  # stamp of the last change
    stamp_s: float = -math.inf  # newest stamp seen; older edges are stale
    before: tuple[bool | None, float] = (None, -math.inf)  # state and since before that change


class LevelControl:
    """See the module docstring; every time comes from the caller (the node clock)."""

    def __init__(self, settings: LevelSettings) -> None:
        self.settings = settings
        self._sensors = tuple(_Sensor(index) for index in settings.watched)
        self._by_index = {sensor.index: sensor for sensor in self._sensors}
        off = settings.mode is LevelMode.OFF
        self._state = LevelState.OFF if off else LevelState.FEEDING
        self._reason = self._fault = ""
        self._now_s = -math.inf  # latest update/reset time
        self._epoch_s = -math.inf  # no timer counts from before this (start, reset, restart)
        self._counting = False  # the time-out ran at the last update
        self._count_from_s = -math.inf  # ... since this update
        self.stale_edges = 0  # edges dropped as older than their sensor's newest

    @property
    def state(self) -> LevelState:
        return self._state

    def edge(self, t_s: float, sensor_index: int, present: bool) -> None:
        """A part-present edge of ``sensor_index`` stamped ``t_s`` (``present``: now covered)."""
        _finite("t_s", t_s)
        sensor = self._by_index.get(sensor_index)
        if sensor is None:
            return  # not a watched sensor
        if t_s < sensor.stamp_s:
            self.stale_edges += 1
            return
        sensor.stamp_s = t_s
        if sensor.covered is bool(present):
            return
        if t_s - sensor.since_s <= _SLACK_S and sensor.before[0] is bool(present):
            # back at the instant it changed (touching parts: one leaves as the next arrives, in
            # either order): a light barrier never saw a change, its timers go on
            sensor.covered, sensor.since_s = sensor.before
            return
        sensor.before = (sensor.covered, sensor.since_s)
        sensor.covered, sensor.since_s = bool(present), t_s

    def update(self, t_s: float, feeding: bool) -> LevelDecision:
        """Whether feeding is allowed at ``t_s``; ``feeding``: the drive outputs vibration now."""
        now = self._advance(t_s)
        cfg = self.settings
        if self._state is LevelState.FEEDING:
            full = self._sensors[-1]
            if full.covered and self._held_s(full, now) >= cfg.off_delay_s:
                self._state = LevelState.FULL
                self._reason = (
                    f"track full: sensor {full.index} covered for {_seconds(cfg.off_delay_s)} s"
                )
        elif self._state is LevelState.FULL:
            low, full = self._sensors[0], self._sensors[-1]  # the same sensor in one_sensor mode
            if not low.covered and not full.covered and self._held_s(low, now) >= cfg.on_delay_s:
                self._state, self._reason = LevelState.FEEDING, ""
        counting = bool(feeding) and self._state is LevelState.FEEDING
        if counting and not self._counting:
            self._count_from_s = now
        self._counting = counting
        if counting and cfg.sensor_timeout_s > 0.0:
            quiet_from = max(self._count_from_s, *(sensor.since_s for sensor in self._sensors))
            if now - quiet_from + _SLACK_S >= cfg.sensor_timeout_s:
                self._state, self._counting = LevelState.FAULT, False
                self._fault = self._reason = self._timeout_reason()
        sensors = tuple(sensor.covered for sensor in self._sensors)
        allowed = self._state in (LevelState.OFF, LevelState.FEEDING)
        return LevelDecision(allowed, self._state, self._reason, self._fault, sensors)

    def reset(self, t_s: float) -> None:
        """Clear a latched fault (-> FEEDING) and restart the delay timers and the time-out
        at ``t_s``; sensor states and a pause are kept."""
        self._epoch_s = self._advance(t_s)
        self._counting = False
        if self._state is LevelState.FAULT:
            self._state, self._reason, self._fault = LevelState.FEEDING, "", ""

    # -- internals ---------------------------------------------------------------------------------
    def _advance(self, t_s: float) -> float:
        """The controller's time after a call at ``t_s``: never back, but restarted by a jump."""
        _finite("t_s", t_s)
        if t_s < self._now_s - CLOCK_JUMP_S:  # the clock restarted (sim time): timers start anew
            self._now_s = self._epoch_s = t_s
            self._counting = False
            for sensor in self._sensors:
                sensor.since_s = sensor.stamp_s = -math.inf
        self._now_s = max(self._now_s, t_s)
        if self._epoch_s == -math.inf:
            self._epoch_s = self._now_s  # the first call: timers count from here
        for sensor in self._sensors:
            if sensor.stamp_s > self._now_s + CLOCK_JUMP_S:  # stamped on another clock
                sensor.since_s = sensor.stamp_s = self._now_s
        return self._now_s

    def _held_s(self, sensor: _Sensor, now: float) -> float:
        """How long ``sensor`` has held its state (counted from the epoch at most), with slack."""
        return now - max(sensor.since_s, self._epoch_s) + _SLACK_S

    def _timeout_reason(self) -> str:
        timeout = _seconds(self.settings.sensor_timeout_s)
        if len(self._sensors) == 1:
            which = f"sensor {self._sensors[0].index}"
        else:
            which = " and ".join(f"{role} sensor {index}" for role, index in self.settings.roles)
        return f"sensor time-out: {which} unchanged for {timeout} s while feeding"
