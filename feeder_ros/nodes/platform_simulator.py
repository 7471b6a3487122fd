"""``platform_simulator``: the feeder's carrier and parts, simulated live by the exact physics core.

Driven by ``drive/command``; publishes what a real feeder's sensors would (the carrier accelerometer
as ``sensor_msgs/Imu``, part-present sensor edges, parts leaving the track) and the ground truth
(carrier state, every part's state). All the physics is :class:`FeederSimulator`; this node turns
parameters and messages into calls on it, and :class:`SimulatorOutputs` turns its samples into
messages (:mod:`feeder_ros.nodes.simulator_outputs`); its services are
:mod:`feeder_ros.nodes.simulator_services`. With ``track_end:=stopper``
parts queue at the end of the track until picked (:class:`TrackEndQueue`, whose module states the
model); the core's exits are then joins to the queue, and a pick is the part leaving the feeder.

Timing: samples lie on exact grids ``k / rate`` of simulated time; each tick advances the simulation
to the tick's target time and publishes every sample up to it, so none is skipped or duplicated.
By default simulated time follows the wall clock (times ``real_time_factor``); with
``use_sim_time`` the node publishes ``/clock`` itself and can run as fast as the machine allows
(``real_time_factor`` = 0).
"""

from __future__ import annotations

import math
import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock as ClockMessage

from feeder_ros.msg import DriveCommand
from feeder_ros.nodes.diagnostics import diagnostic_array, diagnostic_status
from feeder_ros.nodes.platform_simulator_parameters import (
    INTERFACE,
    NODE_DEFAULTS,
    PARAMETERS,
    check_combination,
    parse_positions,
)
from feeder_ros.nodes.ros_parameters import declare_parameters, validator
from feeder_ros.nodes.ros_time import clock_seconds
from feeder_ros.nodes.runner import run_node
from feeder_ros.nodes.simulator_outputs import SimulatorOutputs
from feeder_ros.nodes.simulator_services import SimulatorServices
from feeder_ros.physics.command_policy import Command, Decision, decide
from feeder_ros.physics.drive import DriveError
from feeder_ros.physics.errors import SimulationError
from feeder_ros.physics.parameters import PARAMETER_SPECS, FeederParameters, ParameterError
from feeder_ros.physics.simulation import EventKind, FeederSimulator, PartSpec
from feeder_ros.physics.simulation_health import simulation_health
from feeder_ros.physics.track_end import Picks, TrackEndQueue, pick_edges, start_blocked
from feeder_ros.sensors.accelerometer import AccelerometerModel
from feeder_ros.sensors.part_presence import PartSensorArray

if TYPE_CHECKING:
    from feeder_ros.ros_compat import AnyParameter

PHYSICS_DEFAULTS = FeederParameters().as_dict()
#: a drive command's warning of one kind is logged at most this often
WARNING_PERIOD_S = 5.0

COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class PlatformSimulator(SimulatorServices, Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(INTERFACE.node_name, **kwargs)
        self._values = declare_parameters(
            self, PARAMETERS.values(), {**PHYSICS_DEFAULTS, **NODE_DEFAULTS}
        )
        self._values["use_sim_time"] = self.get_parameter("use_sim_time").value
        check_combination(self._values)
        self.add_on_set_parameters_callback(
            validator(PARAMETERS, check_all=check_combination, current=self._current_values)
        )
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._lock = threading.Lock()
        self._sim_clock = bool(self._values["use_sim_time"])
        self._wall = Clock(clock_type=ClockType.STEADY_TIME)

        pub = self.create_publisher
        self._outputs = SimulatorOutputs(self, bool(self._values["publish_batches"]), self._stamp)
        self._clock_pub = pub(ClockMessage, "/clock", 10) if self._sim_clock else None
        self.create_subscription(DriveCommand, "drive/command", self._on_command, COMMAND_QOS)
        self._create_services()

        self._failure: str | None = None  # the last solver failure, until the drive runs again
        self._late_commands = 0  # commands applied at once because the simulation lagged
        self._warned_at: dict[str, float] = {}  # command warnings: kind -> last logged (s)
        self._start()
        self._timer = self.create_timer(self._values["tick_period_s"], self._tick, clock=self._wall)
        self._diagnostics_pub = pub(DiagnosticArray, "/diagnostics", 10)
        self._report = (clock_seconds(self._wall), self._sim.time_s)
        self.create_timer(1.0, self._publish_diagnostics, clock=self._wall)
        self.get_logger().info(
            f"simulating f_n = {self._sim.params.forward_natural_frequency_hz:.2f} / "
            f"{self._sim.params.backward_natural_frequency_hz:.2f} Hz, "
            f"c = {self._sim.params.damping_ns_per_m:g} N*s/m, "
            f"{self._sim.part_count} parts, "
            + ("sim time (/clock)" if self._sim_clock else "wall-clock paced")
        )

    # -- parameters --------------------------------------------------------------------------
    def _current_values(self) -> dict[str, Any]:
        return dict(self._values)

    def _physics(self) -> FeederParameters:
        physics = FeederParameters.from_mapping({k: self._values[k] for k in PARAMETER_SPECS})
        if self._queue is None:
            return physics
        self._queue.set_track_length(physics.track_length_m)  # the stopper; the core: the tail
        return physics.with_changes(track_length_m=self._queue.core_track_length_m)

    def _follow_queue(self) -> None:
        """The core's track ends at the queue's tail (where parts join it)."""
        end = (
            self._sim.params.track_length_m
            if self._queue is None
            else self._queue.core_track_length_m
        )
        if end != self._sim.params.track_length_m:
            self._sim.set_parameters(self._sim.params.with_changes(track_length_m=end))

    def _apply_parameters(self, parameters: list[AnyParameter]) -> None:
        changed = {p.name for p in parameters if p.name in PARAMETERS}
        with self._lock:
            for parameter in parameters:
                if parameter.name in PARAMETERS:
                    self._values[parameter.name] = parameter.value
            if changed & set(PARAMETER_SPECS):
                before = self._sim.params
                self._sim.set_parameters(self._physics())  # the carrier state carries over
                after = self._sim.params
                if (before.forward_natural_frequency_hz, before.backward_natural_frequency_hz) != (
                    after.forward_natural_frequency_hz,
                    after.backward_natural_frequency_hz,
                ):
                    self.get_logger().info(
                        f"plant changed live at t = {self._sim.time_s:.3f} s: f_n = "
                        f"{after.forward_natural_frequency_hz:.2f} / "
                        f"{after.backward_natural_frequency_hz:.2f} Hz (were "
                        f"{before.forward_natural_frequency_hz:.2f} / "
                        f"{before.backward_natural_frequency_hz:.2f} Hz)"
                    )
            if changed & {
                "imu_noise_density_mps2_per_sqrt_hz",
                "imu_bias_mps2",
                "imu_saturation_mps2",
                "imu_seed",
                "imu_gain",
                "imu_misalignment_deg",
            }:
                self._accelerometer = self._make_accelerometer()
            if "feed_interval_s" in changed:
                self._last_feed_s = self._sim.time_s  # feeding counts from the change
            if "pick_interval_s" in changed:
                self._last_pick_s = self._sim.time_s
            if "real_time_factor" in changed:
                self._rebase_pacing()

    # -- simulation state ----------------------------------------------------------------------
    def _make_accelerometer(self) -> AccelerometerModel:
        return AccelerometerModel(
            rate_hz=self._values["imu_rate_hz"],
            noise_density=self._values["imu_noise_density_mps2_per_sqrt_hz"],
            bias=self._values["imu_bias_mps2"],
            saturation=self._values["imu_saturation_mps2"],
            gravity=self._values["gravity_mps2"],
            seed=self._values["imu_seed"],
            gain=self._values["imu_gain"],
            misalignment_deg=self._values["imu_misalignment_deg"],
        )

    def _start(self) -> None:
        """(Re)start the simulation at t = 0 with the initial parts and no drive."""
        self._queue = None
        if self._values["track_end"] == "stopper":
            self._queue = TrackEndQueue(
                self._values["track_length_m"], self._values["part_length_m"]
            )
        physics = self._physics().with_changes(drive_amplitude_n=0.0)
        count = self._values["initial_parts"]
        start, spacing = self._values["part_start_m"], self._values["part_spacing_m"]
        parts = [PartSpec(position_m=start + i * spacing) for i in range(count)]
        self._sim = FeederSimulator(physics, parts)
        self._sim.advance(0.0)  # compiles (or loads the cached) solver before the node serves
        self._accelerometer = self._make_accelerometer()
        self._sensors = PartSensorArray(
            parse_positions(self._values["sensor_positions_m"]), self._values["part_length_m"]
        )
        self._imu_index = 1  # sample k at k / rate; k = 0 is the state at rest, not published
        self._state_index = 1
        self._parts_index = 1
        self._outputs.restart(count)
        self._feeds_blocked = 0  # see _bowl_feed
        self._last_feed_s = 0.0
        self._last_pick_s = 0.0
        self._epoch_ns = 0 if self._sim_clock else self.get_clock().now().nanoseconds
        self._command_deadline_s = math.inf
        self._drive = (physics.drive_frequency_hz, 0.0)
        self._rebase_pacing()

    def _rebase_pacing(self) -> None:
        self._pace_wall_s = clock_seconds(self._wall)
        self._pace_sim_s = self._sim.time_s

    def _stamp(self, t_s: float) -> TimeMsg:
        sec, nanosec = divmod(self._epoch_ns + round(t_s * 1e9), 1_000_000_000)
        return TimeMsg(sec=sec, nanosec=nanosec)

    def _sim_time_of(self, stamp: Any) -> float:
        return (Time.from_msg(stamp).nanoseconds - self._epoch_ns) * 1e-9

    # -- inputs --------------------------------------------------------------------------------
    def _on_command(self, message: DriveCommand) -> None:
        stamp = message.header.stamp
        with self._lock:
            now = self._sim.time_s
            command = Command(
                message.enabled,
                message.frequency_hz,
                message.amplitude_n,
                message.ramp_time_s,
                None if stamp.sec == 0 and stamp.nanosec == 0 else self._sim_time_of(stamp),
                f"{stamp.sec}.{stamp.nanosec:09d}",
            )
            decision = decide(
                command, now, self._lag_s(), self._values["command_timeout_s"], self._drive
            )
            self._warn(decision)
            if decision.action == "stop":
                self._stop_drive(now)
            if decision.action not in ("schedule", "refresh"):
                return
            self._late_commands += decision.late
            if decision.action == "schedule":
                drive = (decision.frequency_hz, decision.amplitude_n)
                try:
                    self._sim.set_drive(*drive, at_time_s=decision.at_s, ramp_s=decision.ramp_s)
                except (DriveError, ParameterError) as error:  # e.g. a ramp over MAX_TIME_S
                    self.get_logger().warning(
                        f"ignoring drive command: {error}", throttle_duration_sec=5.0
                    )
                    return
                self._drive = drive
                if decision.amplitude_n > 0.0:
                    self._failure = None  # driven again: the next failure reports itself
            self._command_deadline_s = decision.deadline_s

    def _warn(self, decision: Decision) -> None:
        """Log a command's warning, at most once per 5 s for each kind of problem (rclpy's
        throttle counts per call site: one kind repeated would hide the others)."""
        if not decision.warning:
            return
        now = time.monotonic()
        if now - self._warned_at.get(decision.problem, -math.inf) >= WARNING_PERIOD_S:
            self._warned_at[decision.problem] = now
            self.get_logger().warning(decision.warning)

    def _recover(self, error: SimulationError) -> None:
        """The solver cannot continue (for example an undamped branch driven exactly at its
        natural frequency): the simulation restarts at rest with no drive, and the failure is
        logged and reported on /diagnostics (ERROR) until the next command drives again."""
        t = self._sim.time_s
        self.get_logger().error(
            f"simulation failed at t = {t:.6f} s with drive {self._drive[0]:g} Hz / "
            f"{self._drive[1]:g} N: {error}; restarted at rest with the drive off",
            throttle_duration_sec=5.0,
        )
        self._start()
        self._failure = f"simulation failed at t = {t:.6f} s ({error}); restarted at rest"

    def _stop_drive(self, at_s: float) -> None:
        if self._drive[1] != 0.0:
            self._sim.set_drive(self._drive[0], 0.0, at_time_s=at_s)
            self._drive = (self._drive[0], 0.0)
        self._command_deadline_s = math.inf

    # -- the loop ------------------------------------------------------------------------------
    def _schedule_time(self) -> float:
        """Where the paced simulation should be now (simulated time)."""
        elapsed = clock_seconds(self._wall) - self._pace_wall_s
        return self._pace_sim_s + elapsed * float(self._values["real_time_factor"])

    def _lag_s(self) -> float:
        """How far the simulation trails its paced schedule (0 when unpaced or ahead)."""
        if self._values["real_time_factor"] == 0.0:
            return 0.0
        return max(self._schedule_time() - self._sim.time_s, 0.0)

    def _target_time(self) -> float:
        step = float(self._values["max_step_s"])
        if self._values["real_time_factor"] == 0.0:
            return self._sim.time_s + step
        # never more than max_step_s in one step (after a stall, catch up in steps)
        return min(self._schedule_time(), self._sim.time_s + step)

    def _behind(self) -> bool:
        """Whether the paced schedule is a whole step (max_step_s) or more ahead: a step was cut
        short by max_step_s, not one that merely trails the clock by the time it took."""
        with self._lock:
            ahead = self._schedule_time() - self._sim.time_s
            return ahead >= float(self._values["max_step_s"])

    def _tick(self) -> None:
        """One timer tick: steps of at most max_step_s until the schedule is caught up (paced)
        or the tick's time is up (unpaced), then return, so that services and parameter changes
        are served between ticks. A tick is not limited to one step: a real_time_factor above
        max_step_s / tick_period_s (5 with the defaults) is reached too."""
        started = time.perf_counter()
        budget = 0.8 * float(self._values["tick_period_s"])
        while True:
            self._step()
            if time.perf_counter() - started > budget:
                return
            if self._values["real_time_factor"] != 0.0 and not self._behind():
                return

    def _step(self) -> None:
        with self._lock:
            target = self._target_time()
            if target <= self._sim.time_s:
                return
            try:
                if target > self._command_deadline_s:
                    self._advance(self._command_deadline_s)
                    self._stop_drive(self._sim.time_s)
                self._feed(target)
                self._advance(target)
            except SimulationError as error:
                self._recover(error)
                return
        if self._clock_pub is not None:
            self._clock_pub.publish(ClockMessage(clock=self._stamp(target)))

    def _publish_diagnostics(self) -> None:
        with self._lock:
            wall_now = clock_seconds(self._wall)
            sim_now = self._sim.time_s
            wall_then, sim_then = self._report
            self._report = (wall_now, sim_now)
            factor = self._values["real_time_factor"]
            lag = 0.0
            if factor > 0.0:
                lag = self._pace_sim_s + (wall_now - self._pace_wall_s) * factor - sim_now
            on_track = self._sim.part_count - self._outputs.parts_out
            achieved = (sim_now - sim_then) / max(wall_now - wall_then, 1e-9)
            late = self._late_commands
            plant = self._sim.params
            values = {
                "simulated_time_s": f"{sim_now:.6f}",
                "achieved_real_time_factor": f"{achieved:.3f}",
                "requested_real_time_factor": f"{factor:g}",
                "lag_behind_schedule_s": f"{lag:.4f}",
                "drive_commands_applied_late": str(late),
                "imu_samples_published": str(self._imu_index - 1),
                "state_samples_published": str(self._state_index - 1),
                "parts_on_track": str(on_track),
                "parts_out_total": str(self._outputs.parts_out),
                "feeds_skipped_start_blocked": str(self._feeds_blocked),
                "track_end": self._values["track_end"],
                "drive_frequency_hz": f"{self._drive[0]:g}",
                "drive_amplitude_n": f"{self._drive[1]:g}",
                "forward_natural_frequency_hz": f"{plant.forward_natural_frequency_hz:.4g}",
                "backward_natural_frequency_hz": f"{plant.backward_natural_frequency_hz:.4g}",
            }
            values |= self._queue.status() if self._queue is not None else {}
            failure = self._failure
        level, text = simulation_health(
            failure, lag, achieved, factor, late, float(self._values["max_lag_s"])
        )
        name = f"{self.get_fully_qualified_name()}: simulation"
        status = diagnostic_status(name, level, text, "simulated feeder", values)
        self._diagnostics_pub.publish(diagnostic_array(self._stamp(sim_now), status))

    def _feed(self, target: float) -> None:
        """The bowl's feeds and the robot's periodic picks due by ``target``, in time order."""
        feed = self._values["feed_interval_s"]
        pick = self._values["pick_interval_s"] if self._queue is not None else 0.0
        while True:
            next_feed = self._last_feed_s + feed if feed > 0.0 else math.inf
            next_pick = self._last_pick_s + pick if pick > 0.0 else math.inf
            t = min(next_feed, next_pick)
            if t > target:
                return
            self._advance(t)
            if t == next_feed:  # a skipped feed waits for the next interval
                self._last_feed_s = t
                self._bowl_feed(self._values["part_start_m"])
            if t == next_pick and self._queue is not None:
                self._last_pick_s = t
                self._queue.periodic_pick()

    def _bowl_feed(self, start: float) -> None:
        """A part at ``start`` if the queue has room and the bowl's exit is free (skips counted)."""
        if self._queue is not None and not self._queue.admit_feed(start):
            return  # the queue reached the start (counted by the queue)
        if start_blocked(self._sim.track_positions(), start, self._sensors.part_length_m):
            self._feeds_blocked += 1
        else:
            self._sim.spawn_part(PartSpec(position_m=start), at_rest=True)

    def _grid(self, index: int, rate: float, t_end: float) -> tuple[np.ndarray, int]:
        last = math.floor(t_end * rate + 1e-9)
        if last < index:
            return np.zeros(0), index
        return np.arange(index, last + 1) / rate, last + 1

    def _advance(self, t_end: float) -> None:
        if t_end <= self._sim.time_s:
            return
        imu_t, self._imu_index = self._grid(self._imu_index, self._values["imu_rate_hz"], t_end)
        state_t, self._state_index = self._grid(
            self._state_index, self._values["state_rate_hz"], t_end
        )
        parts_t, self._parts_index = self._grid(
            self._parts_index, self._values["parts_rate_hz"], t_end
        )
        times = np.union1d(np.union1d(imu_t, state_t), parts_t)
        queue, picks, t_start = self._queue, Picks(), self._sim.time_s
        if queue is not None:  # both ends sampled: where parts meet the queue, or jump in it
            times = np.union1d(times, (t_start, t_end))
            picks = queue.take_picks()
            self._follow_queue()
        if times.size:
            t_end = max(t_end, float(times[-1]))  # k / rate may round just above t_end
        segments = self._sim.drive.segments()
        result = self._sim.advance(t_end, times)
        exits = result.event_kind == EventKind.PART_EXIT
        if queue is None:  # exits left the feeder; with a stopper they joined the queue
            self._outputs.exits(result.event_t_s[exits], result.event_part[exits])
        else:
            self._outputs.exits(np.full(len(picks.parts), t_start), picks.parts)
        if times.size == 0:
            return
        accel = result.carrier_a_mps2
        if imu_t.size:
            rows = np.searchsorted(times, imu_t)
            self._outputs.imu(
                imu_t,
                self._accelerometer.measure(accel[rows]),
                self._values["imu_frame_id"],
                1.0 / self._values["imu_rate_hz"],
                self._accelerometer.sigma,
            )
        if state_t.size:
            rows = np.searchsorted(times, state_t)
            segment = np.clip(np.searchsorted(segments.start_s, state_t, "right") - 1, 0, None)
            columns: dict[str, np.ndarray] = {
                "displacement_m": result.carrier_x_m[rows],
                "velocity_mps": result.carrier_v_mps[rows],
                "acceleration_mps2": accel[rows],
                "stiffness_branch": result.branch[rows],
                "drive_frequency_hz": segments.omega_rad_s[segment] / (2.0 * math.pi),
                "drive_amplitude_n": segments.amplitude_n[segment],
                "drive_force_n": segments.force(state_t),
            }
            self._outputs.states(state_t, columns, 1.0 / self._values["state_rate_hz"])
        track = result.part_x_m - result.carrier_x_m[:, None]
        if queue is None:
            edges = self._sensors.update(times, track)
        else:
            before = queue.before_picks(track[0], picks)
            queue.settle(times, track, result.event_t_s[exits], result.event_part[exits])
            self._follow_queue()
            edges = pick_edges(self._sensors, times, track, before, picks)
        self._outputs.sensor_edges(edges)
        if parts_t.size:
            rows = np.searchsorted(times, parts_t)
            for j, row in enumerate(rows):
                self._outputs.parts(parts_t[j], result, row, track[row], queue)


NODE_CLASS = PlatformSimulator


def main(args: list[str] | None = None) -> int:
    return run_node(PlatformSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
