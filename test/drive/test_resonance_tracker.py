"""Resonance tracking without ROS: the tracker against synthetic plants whose speed peak moves, the
exact feeder simulator with a live stiffness change, and refusal of settings that cannot work."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.resonance_tracker import (
    FUTURE_STAMP_TOLERANCE_S,
    ResonanceTracker,
    TrackerCommand,
    TrackerError,
    TrackerMode,
    TrackerSettings,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import FeederSimulator, PartSpec, simulate_many

LIMITS = DriveLimits(min_frequency_hz=10.0, max_frequency_hz=30.0, max_amplitude_percent=80.0)
FAST = TrackerSettings(
    dither_hz=0.3,
    dither_period_s=3.0,
    settle_s=0.8,
    gain_hz2=1.5,
    max_step_hz=0.5,
    amplitude_kp_percent=5.0,
    amplitude_ki_percent=20.0,
    max_amplitude_step_percent=5.0,
    feedback_timeout_s=2.0,
)


def lorentz_speed(peak_hz: Callable[[float], float], gain: Callable[[float], float]) -> Callable:
    """v(f, A, t): an asymmetric resonance peak at ``peak_hz(t)``, proportional to amplitude."""

    def speed(f: float, a: float, t: float) -> float:
        x = (f - peak_hz(t)) / (1.5 if f < peak_hz(t) else 2.5)  # steeper below the peak
        return gain(t) * a / (1.0 + x * x)

    return speed


@dataclass
class Loop:
    """The tracker closing the loop over a plant: the drive follows the commands with the limits'
    ramp rates, the speed lags the drive (first order, 0.2 s), readings arrive every 50 ms
    stamped 0.1 s late with 1 % noise (and none while ``silent(t)``)."""

    tracker: ResonanceTracker
    speed: Callable[[float, float, float], float]
    limits: DriveLimits = LIMITS
    silent: Callable[[float], bool] = lambda t: False
    noise: float = 0.01
    dt: float = 0.05
    t: float = 0.0
    f: float = 20.0
    a: float = 30.0
    v: float = 0.0
    commands: list[tuple[float, TrackerCommand]] = field(default_factory=list)
    trace: list[tuple[float, float, float, float]] = field(default_factory=list)  # t f a v
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(7))

    def start(self, target: float) -> None:
        self.v = self.speed(self.f, self.a, 0.0)
        self._apply(self.tracker.start(self.t, self.f, self.a, target))

    def _apply(self, command: TrackerCommand | None) -> None:
        if command is not None:
            self.commands.append((self.t, command))
            self.f, self.a = command.frequency_hz, command.amplitude_percent

    def run(self, until_s: float) -> None:
        delay: list[tuple[float, float]] = []
        while self.t < until_s:
            self.t = round(self.t + self.dt, 9)
            goal = self.speed(self.f, self.a, self.t)
            self.v += (goal - self.v) * (1.0 - math.exp(-self.dt / 0.2))
            self.trace.append((self.t, self.f, self.a, self.v))
            if not self.silent(self.t):
                reading = self.v * (1.0 + self.noise * self.rng.standard_normal())
                delay.append((self.t, reading))
            while delay and delay[0][0] <= self.t - 0.1:
                self.tracker.feedback(*delay.pop(0))
            self._apply(self.tracker.update(self.t))

    def mean_speed(self, t0: float, t1: float) -> float:
        rows = [v for t, _, _, v in self.trace if t0 <= t <= t1]
        return float(np.mean(rows))


def test_converges_to_a_moving_peak_and_holds_the_target_speed() -> None:
    peak = lambda t: 20.0 if t < 90.0 else 18.5  # noqa: E731 - stiffness drops at 90 s
    loop = Loop(ResonanceTracker(FAST, LIMITS), lorentz_speed(peak, lambda t: 0.5e-3))
    loop.f = 21.5  # the speed model's set point: on the flank
    loop.start(target=0.012)
    loop.run(90.0)
    status = loop.tracker.status(loop.t)
    assert status.mode is TrackerMode.ACTIVE
    assert status.centre_frequency_hz == pytest.approx(20.0, abs=0.25)
    assert loop.mean_speed(60.0, 90.0) == pytest.approx(0.012, rel=0.03)
    moved = loop.tracker.status(loop.t).centre_frequency_hz
    loop.run(180.0)
    status = loop.tracker.status(loop.t)
    assert status.centre_frequency_hz == pytest.approx(18.5, abs=0.25)
    assert moved - status.centre_frequency_hz > 1.2
    assert loop.mean_speed(150.0, 180.0) == pytest.approx(0.012, rel=0.03)
    # at the peak the least amplitude gives the target: 0.012 / 0.5e-3 = 24 %, plus the dither's
    # small loss of speed off the peak
    assert status.amplitude_percent == pytest.approx(24.0, rel=0.05)
    assert status.cycles >= 50  # a 3 s cycle, lengthened only by the readings' 0.1 s delay


def test_the_amplitude_trim_follows_a_load_change_at_a_fixed_peak() -> None:
    gain = lambda t: 0.5e-3 if t < 60.0 else 0.35e-3  # noqa: E731 - heavier load: less speed
    loop = Loop(ResonanceTracker(FAST, LIMITS), lorentz_speed(lambda t: 20.0, gain))
    loop.start(target=0.012)
    loop.run(60.0)
    before = loop.tracker.status(loop.t).amplitude_percent
    loop.run(150.0)
    status = loop.tracker.status(loop.t)
    assert status.amplitude_percent == pytest.approx(before / 0.7, rel=0.05)
    assert status.centre_frequency_hz == pytest.approx(20.0, abs=0.25)
    assert loop.mean_speed(120.0, 150.0) == pytest.approx(0.012, rel=0.03)


def test_a_backward_target_tracks_the_peak_of_backward_speed() -> None:
    backward = lorentz_speed(lambda t: 24.0, lambda t: -0.4e-3)
    loop = Loop(ResonanceTracker(FAST, LIMITS), backward)
    loop.f = 22.5
    loop.start(target=-0.010)
    loop.run(120.0)
    status = loop.tracker.status(loop.t)
    assert status.centre_frequency_hz == pytest.approx(24.0, abs=0.25)
    assert loop.mean_speed(90.0, 120.0) == pytest.approx(-0.010, rel=0.03)


def test_stale_feedback_holds_the_centre_and_recovers() -> None:
    silent = lambda t: 40.0 <= t < 50.0  # noqa: E731
    loop = Loop(
        ResonanceTracker(FAST, LIMITS),
        lorentz_speed(lambda t: 20.0, lambda t: 0.5e-3),
        silent=silent,
    )
    loop.start(target=0.012)
    loop.run(40.0)
    loop.run(42.3)  # the last reading (stamped 39.95 s) is more than feedback_timeout_s old
    status = loop.tracker.status(loop.t)
    assert status.mode is TrackerMode.HOLD
    assert "speed feedback stale" in status.reason
    held = loop.commands[-1]
    assert held[1] == TrackerCommand(status.centre_frequency_hz, status.amplitude_percent)
    loop.run(50.0)
    assert loop.commands[-1] == held, "nothing changes while holding (no dither, no trim)"
    loop.run(51.0)
    assert loop.tracker.mode is TrackerMode.ACTIVE
    assert loop.commands[-1][0] > 50.0, "fresh feedback: a new cycle starts"
    loop.run(90.0)
    assert loop.mean_speed(70.0, 90.0) == pytest.approx(0.012, rel=0.03)


def test_feedback_stamped_far_ahead_is_ignored_and_the_tracker_holds() -> None:
    """A reading stamped ahead of the tracker's clock (another clock: wall time against sim
    time) would count as fresh until the clock reaches it; it is refused, so silence still
    leads to HOLD after feedback_timeout_s."""
    loop = Loop(ResonanceTracker(FAST, LIMITS), lorentz_speed(lambda t: 20.0, lambda t: 0.5e-3))
    loop.start(target=0.012)
    loop.run(20.0)
    tracker = loop.tracker
    assert tracker.feedback(loop.t + 0.5, 0.012)  # within the tolerance: taken
    assert not tracker.feedback(loop.t + FUTURE_STAMP_TOLERANCE_S + 0.01, 0.012)
    assert not tracker.feedback(1e9, 0.012)
    assert not tracker.feedback(loop.t, math.nan)
    loop.silent = lambda t: True
    loop.run(23.0)  # no reading since 20.5 s: stale after 2 s
    status = tracker.status(loop.t)
    assert status.mode is TrackerMode.HOLD
    assert "speed feedback stale" in status.reason
    assert status.feedback_age_s == pytest.approx(loop.t - 20.5, abs=1e-9)


def test_limits_bands_and_ramps_are_respected() -> None:
    limits = DriveLimits(
        min_frequency_hz=10.0,
        max_frequency_hz=30.0,
        max_amplitude_percent=40.0,
        max_frequency_rate_hz_per_s=0.5,  # 0.6 Hz of dither swing takes 1.2 s
        forbidden_bands_hz=((21.0, 23.0),),
    )
    # the peak lies in the forbidden band: the tracker stops at its edge, dither included
    loop = Loop(
        ResonanceTracker(FAST, limits),
        lorentz_speed(lambda t: 22.5, lambda t: 0.5e-3),
        limits=limits,
    )
    loop.f = 18.0
    loop.start(target=0.015)
    loop.run(150.0)
    frequencies = [c.frequency_hz for _, c in loop.commands]
    amplitudes = [c.amplitude_percent for _, c in loop.commands]
    assert all(limits.forbidden_band_of(f) is None for f in frequencies)
    assert all(10.0 <= f <= 30.0 for f in frequencies)
    assert max(amplitudes) <= 40.0
    assert loop.tracker.status(loop.t).centre_frequency_hz == pytest.approx(21.0 - 0.3, abs=0.05)
    # a half-period is measured only once the rate-limited ramp to it is done
    previous = TrackerCommand(18.0, 30.0)
    for (t0, command), (t1, _) in zip(loop.commands, loop.commands[1:], strict=False):
        ramp = limits.minimum_ramp_time_s(
            previous.frequency_hz,
            previous.amplitude_percent,
            command.frequency_hz,
            command.amplitude_percent,
        )
        assert t1 - t0 >= ramp + FAST.half_period_s - 1e-9
        previous = command
    assert any(
        t1 - t0 > 1.2 + FAST.half_period_s
        for (t0, _), (t1, _) in zip(loop.commands, loop.commands[1:], strict=False)
    )


def test_an_unreachable_target_saturates_without_windup() -> None:
    gain = lambda t: 0.1e-3 if t < 60.0 else 0.6e-3  # noqa: E731
    loop = Loop(ResonanceTracker(FAST, LIMITS), lorentz_speed(lambda t: 20.0, gain))
    loop.start(target=0.012)
    loop.run(60.0)
    status = loop.tracker.status(loop.t)
    assert status.amplitude_percent == 80.0
    assert status.amplitude_limited
    loop.run(61.5 + 2 * FAST.dither_period_s)  # two cycles at the new gain
    # a wound-up integrator would stay at the limit; this one comes straight off it
    assert loop.tracker.status(loop.t).amplitude_percent <= 80.0 - 2 * 5.0 + 1e-9
    loop.run(150.0)
    assert not loop.tracker.status(loop.t).amplitude_limited
    assert loop.mean_speed(120.0, 150.0) == pytest.approx(0.012, rel=0.03)


def test_a_clock_jumping_back_restarts_the_cycle() -> None:
    loop = Loop(ResonanceTracker(FAST, LIMITS), lorentz_speed(lambda t: 20.0, lambda t: 0.5e-3))
    loop.start(target=0.012)
    loop.run(20.0)
    command = loop.tracker.update(3.0)
    assert command is not None
    assert loop.tracker.mode is TrackerMode.ACTIVE


def test_a_clock_jumping_back_while_holding_keeps_holding_the_centre_then_resumes() -> None:
    tracker = ResonanceTracker(FAST, LIMITS)
    loop = Loop(tracker, lorentz_speed(lambda t: 20.0, lambda t: 0.5e-3))
    loop.start(target=0.012)
    loop.run(20.0)
    tracker.update(25.0)  # no reading for 5 s: HOLD at the centre
    assert tracker.mode is TrackerMode.HOLD
    centre = tracker.status(25.0).centre_frequency_hz
    command = tracker.update(0.5)  # e.g. the simulator was reset (sim time)
    assert command is not None
    assert command.frequency_hz == centre, "holding: the centre, not a dithered frequency"
    assert tracker.mode is TrackerMode.HOLD
    tracker.feedback(1.0, 0.012)  # fresh readings on the new clock end the hold
    assert tracker.update(1.1) is not None
    assert tracker.mode is TrackerMode.ACTIVE


def test_new_settings_while_holding_move_the_centre_out_of_a_band() -> None:
    limits = DriveLimits(
        min_frequency_hz=10.0, max_frequency_hz=40.0, forbidden_bands_hz=((28.0, 29.0),)
    )
    tracker = ResonanceTracker(FAST, limits)
    loop = Loop(tracker, lorentz_speed(lambda t: 29.6, lambda t: 0.5e-3), limits=limits, f=29.6)
    loop.start(target=0.012)
    loop.run(10.0)
    tracker.update(14.0)  # stale: HOLD
    assert tracker.mode is TrackerMode.HOLD
    wide = TrackerSettings(**{**FAST.__dict__, "dither_hz": 1.0})
    assert tracker.update_settings(wide, 14.0) is None  # holding: no new set point yet
    centre = tracker.status(14.0).centre_frequency_hz
    assert centre - 1.0 >= 29.0, "the wider dither must not reach into the band on resuming"


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"dither_hz": math.nan}, "dither_hz=nan is not finite"),
        ({"gain_hz2": math.inf}, "gain_hz2=inf is not finite"),
        ({"dither_hz": 0.0}, "dither_hz=0.0 must be > 0"),
        ({"max_step_hz": -1.0}, "max_step_hz=-1.0 must be > 0"),
        ({"amplitude_ki_percent": -0.1}, "amplitude_ki_percent=-0.1 must be >= 0"),
        ({"settle_s": 2.0, "dither_period_s": 4.0}, "leaves no time to measure"),
        ({"feedback_timeout_s": 1.0, "settle_s": 1.2}, "must exceed settle_s"),
        ({"dither_hz": True}, "is not a number"),
    ],
)
def test_bad_settings_are_refused_naming_the_value(changes: dict[str, object], needle: str) -> None:
    values = {**TrackerSettings().__dict__, **changes}
    with pytest.raises(TrackerError) as error:
        TrackerSettings(**values)
    assert needle in str(error.value)


def test_a_dither_wider_than_the_allowed_range_is_refused() -> None:
    narrow = DriveLimits(min_frequency_hz=20.0, max_frequency_hz=20.5)
    with pytest.raises(TrackerError, match=r"dither_hz=0.3 Hz needs more than 0.6 Hz"):
        ResonanceTracker(TrackerSettings(dither_hz=0.3), narrow)
    banded = DriveLimits(
        min_frequency_hz=10.0, max_frequency_hz=30.0, forbidden_bands_hz=((20.0, 29.8),)
    )
    tracker = ResonanceTracker(TrackerSettings(dither_hz=0.3), banded)
    with pytest.raises(TrackerError):
        tracker.update_limits(narrow, 0.0)
    # the start point lies in an interval too narrow for the dither: not started, with the reason
    assert tracker.start(0.0, 29.9, 30.0, 0.01) is None
    assert tracker.mode is TrackerMode.OFF
    assert "does not fit" in tracker.status(0.0).reason
    assert tracker.start(0.0, 15.0, 30.0, 0.0) is None
    assert "target speed 0" in tracker.status(0.0).reason
    assert tracker.start(0.0, math.nan, 30.0, 0.01) is None
    assert tracker.start(0.0, 15.0, 30.0, 0.01) == TrackerCommand(15.3, 30.0)


def test_new_settings_restart_the_cycle_and_keep_the_tracked_point() -> None:
    loop = Loop(ResonanceTracker(FAST, LIMITS), lorentz_speed(lambda t: 20.0, lambda t: 0.5e-3))
    loop.start(target=0.012)
    loop.run(40.0)
    before = loop.tracker.status(loop.t)
    wider = TrackerSettings(**{**FAST.__dict__, "dither_hz": 0.5})
    command = loop.tracker.update_settings(wider, loop.t)
    assert command is not None
    assert abs(command.frequency_hz - before.centre_frequency_hz) == pytest.approx(0.5)
    assert command.amplitude_percent == before.amplitude_percent
    loop.commands.append((loop.t, command))
    loop.f = command.frequency_hz
    loop.run(90.0)
    assert loop.tracker.status(loop.t).centre_frequency_hz == pytest.approx(20.0, abs=0.25)
    assert loop.mean_speed(70.0, 90.0) == pytest.approx(0.012, rel=0.03)
    with pytest.raises(TrackerError):
        loop.tracker.update_settings(
            TrackerSettings(**{**FAST.__dict__, "dither_hz": 10.0}), loop.t
        )


def test_stop_returns_the_centre_to_hold() -> None:
    tracker = ResonanceTracker(FAST, LIMITS)
    assert tracker.stop() is None
    tracker.start(0.0, 20.0, 30.0, 0.01)
    assert tracker.stop("tracking.enabled is false") == TrackerCommand(20.0, 30.0)
    assert tracker.status(1.0).reason == "tracking.enabled is false"
    assert math.isnan(tracker.status(1.0).centre_frequency_hz)


# -- the exact feeder simulator as the plant ----------------------------------------------------


def _true_peak(plant: FeederParameters, amplitude_n: float) -> float:
    """The frequency of the highest steady part speed at this amplitude (0.05 Hz grid)."""
    grid = np.arange(17.0, 23.0, 0.05)
    points = [
        plant.with_changes(drive_frequency_hz=float(f), drive_amplitude_n=amplitude_n) for f in grid
    ]
    speeds = simulate_many(points, 4.0, settle_s=3.0).mean_part_speed_mps
    return float(grid[int(np.argmax(speeds))])


def test_tracks_the_exact_simulator_through_a_live_stiffness_drop() -> None:
    """The realistic (damped) feeder; its plates' Young's modulus drops 15 % at 40 s while the
    carrier keeps moving: the speed peak moves from about 20.5 Hz down to about 19 Hz."""
    limits = DriveLimits(min_frequency_hz=17.0, max_frequency_hz=25.0, max_amplitude_percent=60.0)
    plant = FeederParameters(damping_ns_per_m=200.0, track_length_m=1e3)
    sim = FeederSimulator(plant.with_changes(drive_amplitude_n=0.0), [PartSpec()])
    tracker = ResonanceTracker(FAST, limits)
    f, a, t, change_t = 21.0, 34.0, 0.0, 0.0
    times, positions = [0.0], [0.0]
    command = tracker.start(0.0, f, a, 0.015)
    while t < 100.0:
        if command is not None:
            ramp = limits.minimum_ramp_time_s(f, a, command.frequency_hz, command.amplitude_percent)
            f, a = command.frequency_hz, command.amplitude_percent
            sim.set_drive(f, limits.force_n(a), ramp_s=ramp)
            change_t = t
        t = round(t + 0.05, 9)
        if t == 40.0:
            x, v, _ = sim.carrier_state
            sim.set_parameters(sim.params.with_changes(youngs_modulus_pa=170e9))
            assert sim.carrier_state[:2] == (x, v), "the carrier state carries over the change"
        times.append(t)
        positions.append(float(sim.advance(t, [t]).part_x_m[-1, 0]))
        if t - change_t >= 0.6:  # like the estimator: a mean since the drive change, after a while
            start = max(change_t, t - 1.0)
            tracker.feedback(t, (positions[-1] - np.interp(start, times, positions)) / (t - start))
        command = tracker.update(t)
        if t == 40.0:
            before = tracker.status(t)

    after = tracker.status(t)
    peak_before = _true_peak(plant, limits.force_n(before.amplitude_percent))
    peak_after = _true_peak(
        plant.with_changes(youngs_modulus_pa=170e9), limits.force_n(after.amplitude_percent)
    )
    assert peak_before - peak_after > 1.0
    assert before.centre_frequency_hz == pytest.approx(peak_before, abs=0.3)
    assert after.centre_frequency_hz == pytest.approx(peak_after, abs=0.3)
    tail = np.asarray(times) >= 70.0
    speed = (positions[-1] - np.asarray(positions)[tail][0]) / (t - np.asarray(times)[tail][0])
    assert speed == pytest.approx(0.015, rel=0.03)
