"""Part speed and feed rate against target, with the alarms a feeder cell needs (ROS-free).

Inputs, each with its own time stamp in seconds (the node clock: simulated time and bag replay
work; a stamp earlier than the last one seen means time jumped back and restarts every window):

* the estimator's mean part speed (with its standard uncertainty and confidence),
* part-present sensor edges (transit time between two sensors: the paper's 8.5 cm timing),
* parts leaving the track (the feed rate, parts per minute),
* the drive state (driving or not) and the target speed.

:meth:`SpeedMonitor.evaluate` gives a :class:`MonitorStatus`: the measured values, a level
(OK/WARN/ERROR, as diagnostic_msgs) and a bit set of alarms.

Speed is judged against the estimate's uncertainty: the interval ``speed +- interval_sigma *
uncertainty`` (95 % by default) must lie within the target's tolerance to be "at target"; under-
and overspeed raise when the whole interval lies beyond the tolerance for ``alarm_delay_s`` (and
clear only once the speed is within ``speed_tolerance * clear_ratio``); an interval that straddles
the tolerance's edge is a warning that the estimate cannot confirm the target (an uncalibrated
part model, a noisy carrier), never an OK. Stall, starvation, track full and sensor timeout
raise after their configured times and clear as soon as the condition is gone.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from feeder_ros.physics.parameters import ParameterError, is_number
from feeder_ros.sensors.transits import TransitTimer

__all__ = [
    "ALARM_NAMES",
    "Alarm",
    "MonitorConfig",
    "MonitorStatus",
    "SpeedMonitor",
]


class Alarm:
    """Bit values of ``SpeedStatus.alarms`` (msg/SpeedStatus.msg ALARM_*)."""

    UNDERSPEED = 1
    OVERSPEED = 2
    STALL = 4
    STARVATION = 8
    TRACK_FULL = 16
    SENSOR_TIMEOUT = 32


ALARM_NAMES = {
    Alarm.UNDERSPEED: "underspeed",
    Alarm.OVERSPEED: "overspeed",
    Alarm.STALL: "stall",
    Alarm.STARVATION: "starvation",
    Alarm.TRACK_FULL: "track full",
    Alarm.SENSOR_TIMEOUT: "sensor timeout",
}
_ERROR_ALARMS = Alarm.STALL | Alarm.TRACK_FULL | Alarm.SENSOR_TIMEOUT

OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class MonitorConfig:
    speed_tolerance: float = 0.15  #: relative speed error that raises under/overspeed
    clear_ratio: float = 0.6  #: the alarm clears below speed_tolerance * clear_ratio
    alarm_delay_s: float = 2.0  #: a speed error must last this long to raise
    min_confidence: float = 0.0  #: estimates below this confidence give no speed
    #: the judged interval: the estimate +- this many of its standard uncertainties
    interval_sigma: float = 2.0
    stall_speed_mps: float = 0.5e-3  #: driving with |speed| below this is a stall ...
    stall_time_s: float = 3.0  #: ... for this long
    starvation_time_s: float = 30.0  #: driving and no part seen for this long
    track_full_time_s: float = 10.0  #: a part-present sensor covered this long
    #: no estimate message for this long while driving is a sensor timeout (ERROR); estimates
    #: that keep coming below min_confidence this long are a WARN (no speed to check)
    sensor_timeout_s: float = 2.0
    #: before the first estimate message (start-up): a WARN "waiting" while driving, a sensor
    #: timeout only this long after the drive started
    startup_timeout_s: float = 10.0
    feed_window_s: float = 60.0  #: window of the feed rate
    transit_pair: tuple[int, int] = (0, 1)  #: sensor indices timed for the transit speed
    transit_distance_m: float = 0.085  #: distance between those sensors

    def __post_init__(self) -> None:
        for name in (
            "speed_tolerance",
            "alarm_delay_s",
            "stall_time_s",
            "starvation_time_s",
            "track_full_time_s",
            "sensor_timeout_s",
            "startup_timeout_s",
            "feed_window_s",
            "transit_distance_m",
            "stall_speed_mps",
            "interval_sigma",
        ):
            value = getattr(self, name)
            if not (is_number(value) and math.isfinite(value) and value > 0.0):
                raise ParameterError(f"{name}={value!r} must be finite and > 0")
        for name in ("clear_ratio", "min_confidence"):
            value = getattr(self, name)
            if not (is_number(value) and 0.0 <= value <= 1.0):
                raise ParameterError(f"{name}={value!r} must be in [0, 1]")
        first, second = self.transit_pair
        if first == second or min(first, second) < 0:
            raise ParameterError(f"transit_pair={self.transit_pair!r}: two different sensors")


@dataclass(frozen=True)
class MonitorStatus:
    t_s: float
    target_speed_mps: float  #: nan when no target is set
    estimated_speed_mps: float  #: nan when unknown
    estimated_speed_uncertainty_mps: float  #: its standard uncertainty; nan when unknown
    transit_speed_mps: float  #: nan when no part has been timed yet
    feed_rate_ppm: float
    level: int  #: 0 OK, 1 WARN, 2 ERROR
    alarms: int  #: bit set of Alarm values
    message: str
    details: dict[str, str] = field(default_factory=dict)


class SpeedMonitor:
    def __init__(self, config: MonitorConfig | None = None) -> None:
        self.config = config if config is not None else MonitorConfig()
        self.reset()

    def reconfigure(self, config: MonitorConfig) -> None:
        """New limits from now on; the state (raised alarms, timers, the feed-rate history, the
        target) is kept: a parameter change must not hide an alarm. New transit sensors or
        distance start a new pairing (edges already seen were timed for the old ones)."""
        old = self.config
        self.config = config
        if (config.transit_pair, config.transit_distance_m) != (
            old.transit_pair,
            old.transit_distance_m,
        ):
            self._transits = TransitTimer(*config.transit_pair, config.transit_distance_m)

    def reset(self) -> None:
        """Forget everything (also done when time jumps backwards)."""
        self._last_t = -math.inf
        self._driving = False
        self._driving_since = math.nan
        self._target = math.nan
        self._speed = math.nan
        self._sigma = math.nan
        self._speed_t = -math.inf
        self._heard_t = -math.inf  # the last estimate message, whatever its confidence
        self._listen_t = -math.inf  # listening since (see resumed)
        self._heard_confidence = math.nan
        self._heard_finite = False
        self._speed_error_since = math.nan
        self._speed_alarm = 0
        self._slow_since = math.nan
        self._last_part_t = math.nan
        self._transit = math.nan
        first, second = self.config.transit_pair
        self._transits = TransitTimer(first, second, self.config.transit_distance_m)
        self._covered_since: dict[int, float] = {}  # sensor -> time its part arrived
        self._exits: deque[float] = deque()
        self.time_jumps = 0

    # -- inputs ------------------------------------------------------------------------------
    def _advance(self, t: float) -> None:
        if not math.isfinite(t):
            raise ParameterError(f"time {t!r} is not finite")
        if t < self._last_t:
            jumps = self.time_jumps + 1
            self.reset()
            self.time_jumps = jumps
        self._last_t = t

    def resumed(self, t: float) -> None:
        """The monitor was not listening until ``t`` (its process stalled, and the inputs sent
        meanwhile are still on their way). Time without an input (an estimate, a confident
        speed, a part, a sensor uncovered) counts from ``t`` at the earliest: a stall is not the
        inputs' silence. The node calls it at every tick of the middleware's catch-up, which
        runs on the wall clock (see :class:`~feeder_ros.nodes.stall_detector.StallDetector`)."""
        self._advance(t)
        self._listen_t = t

    def on_drive(self, t: float, driving: bool, target_speed_mps: float) -> None:
        """The drive state: whether it drives, and the target part speed (nan: none). An
        infinite target raises ``ParameterError`` and changes nothing."""
        if not (math.isnan(target_speed_mps) or math.isfinite(target_speed_mps)):
            raise ParameterError(f"target_speed_mps={target_speed_mps!r} is not finite")
        self._advance(t)
        if driving and not self._driving:
            self._driving_since = t
            self._last_part_t = t  # starvation counts from the start of driving
            self._slow_since = math.nan
        self._driving = driving
        self._target = target_speed_mps

    def on_estimate(
        self, t: float, mean_speed_mps: float, confidence: float, uncertainty_mps: float = 0.0
    ) -> None:
        """An estimate message: its speed counts when it is finite, has a finite uncertainty and
        is at least ``min_confidence`` sure; any message shows that the estimator is alive."""
        self._advance(t)
        self._heard_t = t
        self._heard_confidence = confidence
        self._heard_finite = math.isfinite(mean_speed_mps)
        usable = math.isfinite(mean_speed_mps) and math.isfinite(uncertainty_mps)
        if usable and uncertainty_mps >= 0.0 and confidence >= self.config.min_confidence:
            self._speed = mean_speed_mps
            self._sigma = uncertainty_mps
            self._speed_t = t

    def on_sensor_edge(
        self,
        t: float,
        sensor: int,
        part: int | None,
        present: bool,
        edge_t: float | None = None,
    ) -> None:
        """A part-present sensor edge seen at ``t``; ``part`` is the part id where the sensor
        knows it; ``edge_t`` is when the edge happened by the sensor's own stamp (the transit
        speed is timed with it, so delivery delays do not distort it), default ``t``."""
        self._advance(t)
        self._last_part_t = t
        stamp = t if edge_t is None or not math.isfinite(edge_t) else edge_t
        if present:
            self._covered_since[sensor] = t
        else:
            self._covered_since.pop(sensor, None)
        transit = self._transits.on_edge(stamp, sensor, part, present)
        if transit is not None:
            self._transit = transit.speed_mps

    def on_exit(self, t: float) -> None:
        self._advance(t)
        self._last_part_t = t
        self._exits.append(t)

    # -- output ------------------------------------------------------------------------------
    def evaluate(self, t: float) -> MonitorStatus:
        self._advance(t)
        cfg = self.config
        while self._exits and self._exits[0] < t - cfg.feed_window_s:
            self._exits.popleft()
        driving_for = t - self._driving_since if self._driving else 0.0
        window = min(cfg.feed_window_s, driving_for) if self._driving else cfg.feed_window_s
        # a window shortened to the time since the drive started counts only the exits in it:
        # parts that left before a restart would give a huge rate over a few milliseconds
        exits = sum(1 for exit_t in self._exits if exit_t >= t - window)
        feed_rate = exits * 60.0 / window if window > 0.0 else 0.0

        alarms = 0
        fresh = t - self._speed_t <= cfg.sensor_timeout_s
        speed = self._speed if fresh else math.nan
        # the estimate stream went silent; estimates that keep coming without the confidence to
        # use them are a warning below (the estimator is alive, e.g. settling after a start)
        heard = t - self._heard_t <= cfg.sensor_timeout_s
        no_speed_for = t - max(self._speed_t, self._listen_t)  # listening, no confident speed
        unsure = self._driving and driving_for > cfg.sensor_timeout_s
        unsure = unsure and no_speed_for > cfg.sensor_timeout_s
        # start-up is not a fault: an estimator never heard from is waited for (while driving,
        # up to startup_timeout_s); a stream that was live and went silent is lost, driving or
        # not (the estimator publishes at rest too)
        never_heard = self._heard_t == -math.inf
        waiting = never_heard and driving_for <= cfg.startup_timeout_s
        silent = t - max(self._heard_t, self._listen_t) > cfg.sensor_timeout_s
        if (unsure and not heard and not waiting) or (not never_heard and silent):
            alarms |= Alarm.SENSOR_TIMEOUT

        # stall: driving but the part does not move
        if self._driving and fresh and abs(speed) < cfg.stall_speed_mps:
            if math.isnan(self._slow_since):
                self._slow_since = t
            if t - self._slow_since >= cfg.stall_time_s:
                alarms |= Alarm.STALL
        else:
            self._slow_since = math.nan

        alarms |= self._judge_speed(t, speed if fresh else math.nan)

        if (
            self._driving
            and math.isfinite(self._last_part_t)
            and t - max(self._last_part_t, self._listen_t) >= cfg.starvation_time_s
        ):
            alarms |= Alarm.STARVATION
        covered = self._covered_since.values()
        if any(t - max(since, self._listen_t) >= cfg.track_full_time_s for since in covered):
            alarms |= Alarm.TRACK_FULL

        level = ERROR if alarms & _ERROR_ALARMS else (WARN if alarms else OK)
        names = [name for bit, name in ALARM_NAMES.items() if alarms & bit]
        if names:
            message = ", ".join(names)
        elif unsure and waiting:
            level = WARN
            message = f"waiting for the first speed estimate ({driving_for:.1f} s since the start)"
        elif unsure:
            level = WARN
            why = (
                f"confidence {self._heard_confidence:.2f} < {cfg.min_confidence:.2f}"
                if self._heard_finite
                else "no speed in it"
            )
            since = t - max(self._speed_t, self._driving_since, self._listen_t)
            message = f"no confident speed estimate for {since:.1f} s ({why})"
        elif not self._driving:
            message = "idle"
        elif math.isfinite(self._target) and fresh:
            level, message = self._target_message(speed)
        elif math.isfinite(self._target):
            # not "at target" before an estimate says so (sensor timeout raises after a while)
            message = "waiting for a speed estimate"
        else:
            message = "running (no target)"
        details = {
            "driving": str(self._driving).lower(),
            "speed_error_percent": (
                f"{100.0 * (speed - self._target) / abs(self._target):.1f}"
                if math.isfinite(speed) and math.isfinite(self._target) and self._target != 0.0
                else "nan"
            ),
            "seconds_since_last_part": (
                f"{t - self._last_part_t:.1f}" if math.isfinite(self._last_part_t) else "nan"
            ),
            "time_jumps_back": str(self.time_jumps),
            "last_estimate_confidence": f"{self._heard_confidence:.3f}",
            "estimate_uncertainty_mps": f"{self._sigma:.3g}" if fresh else "nan",
        }
        return MonitorStatus(
            t_s=t,
            target_speed_mps=self._target,
            estimated_speed_mps=speed,
            estimated_speed_uncertainty_mps=self._sigma if fresh else math.nan,
            transit_speed_mps=self._transit,
            feed_rate_ppm=feed_rate,
            level=level,
            alarms=alarms,
            message=message,
            details=details,
        )

    def _judge_speed(self, t: float, speed: float) -> int:
        """The under/overspeed alarm (with its delay and hysteresis): raised when the whole
        interval ``speed +- interval_sigma * uncertainty`` lies beyond the tolerance."""
        cfg = self.config
        target = self._target
        if not (self._driving and math.isfinite(speed) and math.isfinite(target) and target != 0):
            self._speed_error_since = math.nan
            self._speed_alarm = 0
            return 0
        error = (speed - target) / abs(target)
        if self._beyond_tolerance(speed):
            if math.isnan(self._speed_error_since):
                self._speed_error_since = t
            if t - self._speed_error_since >= cfg.alarm_delay_s:
                self._speed_alarm = Alarm.UNDERSPEED if error < 0 else Alarm.OVERSPEED
        else:
            self._speed_error_since = math.nan
            if abs(error) < cfg.speed_tolerance * cfg.clear_ratio:
                self._speed_alarm = 0
        return self._speed_alarm

    def _beyond_tolerance(self, speed: float) -> bool:
        """The whole interval ``speed +- interval_sigma * uncertainty`` lies outside the target's
        tolerance (under- or overspeed once it lasts ``alarm_delay_s``)."""
        cfg, target = self.config, self._target
        half = cfg.interval_sigma * self._sigma
        return abs(speed - target) - half > cfg.speed_tolerance * abs(target)

    def _target_message(self, speed: float) -> tuple[int, str]:
        """At target only when the whole interval lies within the tolerance; an interval that
        reaches beyond it cannot confirm the target (a warning)."""
        cfg = self.config
        target = self._target
        half = cfg.interval_sigma * self._sigma
        shown_speed = 1e3 * speed if abs(speed) >= 5e-6 else 0.0  # no "-0.00" at rest
        shown = f"{shown_speed:.2f} +- {1e3 * half:.2f} mm/s"
        band = cfg.speed_tolerance * abs(target)
        if abs(speed - target) + half <= band:
            return OK, f"at target ({shown})"
        against = f"{1e3 * target:.2f} mm/s +- {100 * cfg.speed_tolerance:g} %"
        if half > band:  # no estimate this wide could confirm any speed: calibration, noise
            why = "its interval is wider than the tolerance (part model not calibrated yet?)"
        elif self._beyond_tolerance(speed):  # wholly outside: an alarm once it lasts
            why = "the part speed is off target (starting, ramping, or an alarm after its delay)"
        else:
            why = "its interval reaches beyond the tolerance"
        return WARN, f"the estimate cannot confirm the target: {shown} against {against}: {why}"
