"""Vibration-amplitude regulation (:mod:`feeder_ros.nodes.drive_amplitude`).

In process first: the shell on a real rclpy node (its parameters, service and subscription, no
DDS traffic), the real DriveController and the exact carrier physics, ticked as the drive
interface ticks it: when the loop acts and when it lets go, refusals, a live stiffness drop.

Then with real processes: the platform simulator (the demo cell's feeder, config/cell.yaml: 1 kHz
accelerometer in batches, wall-clock paced) and the drive interface with ``amplitude.enabled``,
driven at 30 Hz by an in-process cell controller (with its heartbeat). What is checked is what
reaches the wire: the probe measures the accelerometer's 30 Hz line itself from the simulator's
``imu/batch``, and reads the drive's amplitude on ``drive/state``. The simulator's springs lose
15 % of their stiffness live; the line must come back within 2 % of the set point within 2 s, the
drive's amplitude never above ``max_amplitude_percent``.
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_test_tools import DrainedProcess, call, demo_cell_file, probe_node, wait_until

from feeder_ros.cell import load_cell, parameters_document
from feeder_ros.cli.cell import node_executables
from feeder_ros.drive.amplitude_regulator import AmplitudeSettings, LineAmplitude
from feeder_ros.drive.controller import DriveController
from feeder_ros.drive.limits import DriveLimits
from feeder_ros.examples.cell_controller import CellController
from feeder_ros.msg import AccelerometerBatch, DriveState
from feeder_ros.nodes.drive_amplitude import AmplitudeShell
from feeder_ros.nodes.drive_interface_parameters import (
    AMPLITUDE_DEFAULTS,
    AMPLITUDE_PARAMETERS,
    PARAMETERS,
)
from feeder_ros.nodes.ros_parameters import declare_parameters, validator
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import FeederSimulator
from feeder_ros.sensors.accelerometer import AccelerometerModel
from feeder_ros.srv import SetDrive, SetVibrationAmplitude

BIN = Path(sys.executable).parent
NS = "/amplitude_cell/feeder_1"
F_HZ = 30.0
START_PERCENT = 40.0  # set_drive's amplitude: the loop's starting point
MAX_PERCENT = 60.0  # the drive's limit, which the loop must never pass
SET_POINT_GAIN = 1.1  # the set point: the line at START_PERCENT, times this (needs about 44 %)
TOLERANCE = 0.02  # the line within 2 % of the set point
RECOVERY_S = 2.0  # ... again within 2 s of the stiffness drop


def _double(name: str, value: float) -> ParameterMsg:
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    )


def _bool(name: str, value: bool) -> ParameterMsg:
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
    )


# -- in process ------------------------------------------------------------------------------
TICK_S = 0.02  # the drive interface's tick (publish_rate_hz 50)
EPOCH_S = 1000.0  # node clock and sample stamps at simulated time 0


class Bench:
    """The shell on a plain rclpy node declaring its parameters as the drive interface does, a
    DriveController, and the simulated carrier with its 1 kHz accelerometer (batches per tick)."""

    def __init__(self, node: Any) -> None:
        specs = {spec.name: spec for spec in (*AMPLITUDE_PARAMETERS, PARAMETERS["publish_rate_hz"])}
        batches = {"amplitude.imu_topic": "imu/batch", "amplitude.imu_type": "imu_batch"}
        self.values = declare_parameters(
            node, specs.values(), {**AMPLITUDE_DEFAULTS, **batches, "publish_rate_hz": 50.0}
        )
        node.add_on_set_parameters_callback(validator(specs, current=lambda: self.values))
        node.add_post_set_parameters_callback(
            lambda parameters: self.values.update({p.name: p.value for p in parameters})
        )
        self.node = node
        self.shell = AmplitudeShell(node, self.values)
        limits = DriveLimits(
            min_frequency_hz=10.0, max_frequency_hz=60.0, max_amplitude_percent=60.0
        )
        self.controller = DriveController(limits, heartbeat_timeout_s=2.0)
        self.shell.configure(self.controller)
        self.plant = FeederParameters(damping_ns_per_m=200.0, youngs_modulus_pa=194e9)
        self.sim = FeederSimulator(self.plant)
        self.imu = AccelerometerModel(1000.0, noise_density=0.0015, bias=0.04, seed=2)
        self.last = self.controller.tick(EPOCH_S)
        self.samples = 0  # accelerometer samples published (sample k at k ms)
        self.history: list[tuple[float, float, DriveState]] = []  # sim time, drive %, state
        self.controller.activate(EPOCH_S)
        self.controller.heartbeat(EPOCH_S)

    def subscription_callback(self) -> Any:
        (subscription,) = [s for s in self.node.subscriptions if s.topic_name.endswith("imu/batch")]
        return subscription.callback

    def call(self, value: float) -> Any:
        (service,) = [
            s for s in self.node.services if s.srv_name.endswith("set_vibration_amplitude")
        ]
        request = SetVibrationAmplitude.Request(amplitude_mps2=value)
        return service.callback(request, SetVibrationAmplitude.Response())

    @property
    def now_s(self) -> float:
        return EPOCH_S + self.sim.time_s

    def run(self, seconds: float) -> DriveState:
        """Tick for ``seconds``: the simulator advances and publishes, then the shell's hook,
        the controller's tick, and the output applied, as in the drive interface."""
        on_batch = self.subscription_callback()
        for _ in range(round(seconds / TICK_S)):
            first, self.samples = self.samples + 1, self.samples + round(TICK_S * 1000.0)
            end = self.samples / 1000.0
            times = np.arange(first, self.samples + 1) / 1000.0
            measured = self.imu.measure(self.sim.advance(end, times).carrier_a_mps2)[:, 0]
            batch = AccelerometerBatch(sample_period_s=0.001, acceleration_x_mps2=measured.tolist())
            batch.header.stamp.sec, batch.header.stamp.nanosec = divmod(
                round((EPOCH_S + times[0]) * 1e9), 1_000_000_000
            )
            on_batch(batch)
            self.controller.heartbeat(self.now_s)
            self.shell.tick(self.controller, self.now_s, self.last)
            self.last = self.controller.tick(self.now_s, TICK_S)
            force = self.last.amplitude_n if self.last.enabled else 0.0
            self.sim.set_drive(self.last.frequency_hz, force, ramp_s=self.last.ramp_time_s)
            state = DriveState()
            self.shell.fill_state(state, self.controller)
            self.history.append((self.sim.time_s, self.last.amplitude_percent, state))
        return self.history[-1][2]

    def measured_since(self, t_s: float) -> np.ndarray:
        return np.array([s.measured_amplitude_mps2 for t, _, s in self.history if t >= t_s])


@pytest.fixture
def bench() -> Iterator[Bench]:
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("drive_interface", context=context)
    try:
        bench = Bench(node)
        yield bench
        bench.shell.teardown()
        bench.shell.destroy()
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_the_shell_regulates_and_lets_go_when_it_must(bench: Bench) -> None:
    controller, shell = bench.controller, bench.shell
    assert controller.set_drive(bench.now_s, F_HZ, START_PERCENT, 0.5).reason
    assert controller.start(bench.now_s).success
    state = bench.run(2.0)
    assert not state.amplitude_regulated
    assert math.isnan(state.measured_amplitude_mps2)
    assert shell.diagnostics()["amplitude regulation"] == "off: amplitude.enabled is false"

    # enabled without a set point: it measures (and learns its reach), the drive stays put
    bench.node.set_parameters([Parameter("amplitude.enabled", value=True)])
    state = bench.run(1.0)
    line = state.measured_amplitude_mps2
    assert line > 1.0
    assert not state.amplitude_regulated
    assert bench.last.amplitude_percent == START_PERCENT
    reach = bench.call(math.nan).reachable_max_mps2
    assert reach == pytest.approx(line * MAX_PERCENT / START_PERCENT, rel=0.02)

    # refusals name the value and the range, as a service answer or a parameter; nothing changes
    for value, named in ((math.nan, "nan m/s^2"), (0.0, "0 m/s^2 must be > 0")):
        answer = bench.call(value)
        assert answer.result == SetVibrationAmplitude.Response.REFUSED
        assert named in answer.reason, answer.reason
        assert f"reachable 0 .. {reach:.4g} m/s^2 at 30 Hz" in answer.reason
    result = bench.node.set_parameters([Parameter("amplitude.set_point_mps2", value=2 * reach)])[0]
    assert not result.successful
    assert f"{2 * reach:g} m/s^2 beyond the drive's reach" in result.reason
    controller.speed_mode = True  # (target-speed mode owns the amplitude)
    assert "target-speed mode" in bench.call(line).reason
    controller.speed_mode = False
    assert math.isnan(bench.values["amplitude.set_point_mps2"])

    # a set point: the loop moves the drive there, and back after the springs soften
    set_point = SET_POINT_GAIN * line
    assert bench.call(set_point).result == SetVibrationAmplitude.Response.ACCEPTED
    assert bench.values["amplitude.set_point_mps2"] == set_point
    state = bench.run(4.0)
    assert state.amplitude_regulated
    assert state.amplitude_set_point_mps2 == set_point
    assert np.all(
        np.abs(bench.measured_since(bench.sim.time_s - 1.0) / set_point - 1.0) < TOLERANCE
    )
    drop_s, settled_percent = bench.sim.time_s, bench.last.amplitude_percent
    bench.sim.set_parameters(bench.plant.with_changes(youngs_modulus_pa=0.85 * 194e9))
    bench.run(3.0)
    off = np.abs(bench.measured_since(drop_s) / set_point - 1.0)
    assert off.max() > 0.01  # disturbed (in steady state the line would be 2.2 % higher)
    assert bench.last.amplitude_percent < 0.99 * settled_percent  # ... which the loop took back
    assert np.all(off[-round(1.0 / TICK_S) :] < TOLERANCE)  # back within 2 s
    assert max(percent for _, percent, _ in bench.history) <= MAX_PERCENT
    regulated = bench.last.amplitude_percent

    # the loop scales the output; the set point stays set_drive's, its starting point
    assert controller.set_point.amplitude_percent == START_PERCENT
    assert controller.amplitude_scale == pytest.approx(regulated / START_PERCENT)
    # a new set_drive amplitude is a new starting point: the line is held all the same
    assert controller.set_drive(bench.now_s, F_HZ, 0.9 * START_PERCENT, 0.0).outcome == 0
    state = bench.run(5.0)
    assert state.amplitude_regulated
    assert bench.last.amplitude_percent == pytest.approx(regulated, rel=0.03)
    assert np.all(
        np.abs(bench.measured_since(bench.sim.time_s - 1.0) / set_point - 1.0) < TOLERANCE
    )

    # switched off: the output returns to the set point at the drive's ramp rate (no step)
    bench.node.set_parameters([Parameter("amplitude.enabled", value=False)])
    state = bench.run(1.0)
    assert not state.amplitude_regulated
    assert bench.last.amplitude_percent == pytest.approx(0.9 * START_PERCENT)
    steps = np.diff([percent for _, percent, _ in bench.history[-round(1.0 / TICK_S) - 1 :]])
    assert np.abs(steps).max() <= 50.0 * TICK_S + 1e-9  # max_amplitude_rate_percent_per_s
    bench.node.set_parameters([Parameter("amplitude.enabled", value=True)])
    bench.run(4.0)

    # stopped: reset, and re-probed after the next start
    controller.stop(bench.now_s)
    state = bench.run(2.0)
    assert not state.amplitude_regulated
    assert math.isnan(state.measured_amplitude_mps2)
    assert math.isnan(bench.call(math.nan).reachable_max_mps2)
    assert state.amplitude_set_point_mps2 == set_point  # the set point stays
    assert controller.start(bench.now_s).success
    state = bench.run(3.0)
    assert state.amplitude_regulated
    assert math.isfinite(bench.call(math.nan).reachable_max_mps2)


def _speed_loop_step(controller: DriveController, now_s: float, percent: float) -> None:
    """An outer speed loop's amplitude step, as the drive interface applies one (the speed trim,
    resonance tracking): through set_drive, target-speed mode kept."""
    assert controller.set_drive(now_s, F_HZ, percent, 0.0).outcome == 0
    controller.speed_mode, controller.target_speed_mps = True, 0.01


def test_under_target_speed_mode_the_loop_holds_the_line_the_speed_loops_ask_for(
    bench: Bench,
) -> None:
    controller, shell = bench.controller, bench.shell
    bench.node.set_parameters([Parameter("amplitude.enabled", value=True)])
    _speed_loop_step(controller, bench.now_s, START_PERCENT)
    assert controller.start(bench.now_s).success
    state = bench.run(3.0)
    # the reference: the line per set-point % when the loop took over
    assert state.amplitude_regulated, shell.diagnostics()
    assert shell.diagnostics()["amplitude regulation"].startswith("regulating under target-speed")
    held = state.amplitude_set_point_mps2
    assert state.measured_amplitude_mps2 == pytest.approx(held, rel=TOLERANCE)
    assert bench.last.amplitude_percent == pytest.approx(START_PERCENT, rel=0.01)
    assert "target-speed mode" in bench.call(held).reason  # the speed loops give the line

    # softer springs: the loop takes the output down, the speed loops' % stays
    drop_s = bench.sim.time_s
    bench.sim.set_parameters(bench.plant.with_changes(youngs_modulus_pa=0.85 * 194e9))
    bench.run(3.0)
    off = np.abs(bench.measured_since(drop_s) / held - 1.0)
    assert off.max() > 0.01
    assert np.all(off[-round(1.0 / TICK_S) :] < TOLERANCE)
    assert controller.set_point.amplitude_percent == START_PERCENT
    assert bench.last.amplitude_percent < 0.99 * START_PERCENT

    # a speed-loop step of +10 %: the line follows it, on the softer springs
    _speed_loop_step(controller, bench.now_s, 1.1 * START_PERCENT)
    state = bench.run(4.0)
    assert state.amplitude_set_point_mps2 == pytest.approx(1.1 * held, rel=1e-9)
    assert np.all(
        np.abs(bench.measured_since(bench.sim.time_s - 1.0) / (1.1 * held) - 1.0) < TOLERANCE
    )
    assert max(percent for _, percent, _ in bench.history) <= MAX_PERCENT

    # target-speed mode ends (set_drive), no set point of its own: measuring only, scale back to 1
    assert controller.set_drive(bench.now_s, F_HZ, START_PERCENT, 0.0).outcome == 0
    state = bench.run(2.0)
    assert not state.amplitude_regulated
    assert math.isnan(state.amplitude_set_point_mps2)
    assert bench.last.amplitude_percent == START_PERCENT


# -- live ------------------------------------------------------------------------------------
@dataclass
class Wire:
    """What the probe heard: the accelerometer's x samples and the drive's states."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    t: list[float] = field(default_factory=list)  # sample stamps
    x: list[float] = field(default_factory=list)
    states: list[DriveState] = field(default_factory=list)

    def on_imu(self, message: AccelerometerBatch) -> None:
        stamp = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
        n = len(message.acceleration_x_mps2)
        with self.lock:
            self.t.extend((stamp + message.sample_period_s * np.arange(n)).tolist())
            self.x.extend(message.acceleration_x_mps2)

    def on_state(self, message: DriveState) -> None:
        with self.lock:
            self.states.append(message)

    def last_state(self) -> DriveState:
        with self.lock:
            assert self.states, "no drive/state heard"
            return self.states[-1]

    def lines(self, since_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Window ends and the 30 Hz line of the samples stamped from ``since_s`` on, measured
        as the drive interface does (6 drive periods a window)."""
        with self.lock:
            t, x = np.array(self.t), np.array(self.x)
        t, first = np.unique(t, return_index=True)  # (best effort: order not guaranteed)
        keep = t >= since_s
        measured = LineAmplitude(AmplitudeSettings()).add(t[keep], x[first][keep], F_HZ)
        return (
            np.array([m.t_s for m in measured]),
            np.array([m.amplitude_mps2 for m in measured]),
        )

    def line(self, t0: float, t1: float) -> float:
        """The mean line over the windows ending in [t0, t1]."""
        ends, lines = self.lines(t0)
        inside = lines[ends <= t1]
        assert inside.size >= 3, f"{inside.size} windows in [{t0:.2f}, {t1:.2f}] s"
        return float(inside.mean())


@contextlib.contextmanager
def amplitude_cell(tmp_path: Path) -> Iterator[tuple[Any, Wire, CellController]]:
    """Simulator and drive interface as processes, the drive configured, active and started at
    30 Hz / START_PERCENT (regulation off); yields the probe, what it heard and the controller."""
    drive = {
        "speed_model_enabled": False,
        "speed_trim": {"enabled": False},
        "max_amplitude_percent": MAX_PERCENT,
    }
    cell_file = demo_cell_file(
        tmp_path,
        NS,
        without=("vehicle_estimator", "speed_monitor"),
        parameters={"drive_interface": drive},
    )
    cell = load_cell(cell_file, node_executables())
    parameters = tmp_path / "parameters.yaml"
    parameters.write_text(parameters_document(cell), encoding="utf-8")
    processes = {
        launch.executable: DrainedProcess(
            [str(BIN / launch.executable), *launch.ros_arguments(parameters)]
        )
        for launch in cell.nodes
    }
    wire = Wire()
    passed = False
    try:
        with probe_node("amplitude_probe") as probe:
            sensor = QoSProfile(depth=500, reliability=ReliabilityPolicy.BEST_EFFORT)
            probe.create_subscription(AccelerometerBatch, f"{NS}/imu/batch", wire.on_imu, sensor)
            probe.create_subscription(DriveState, f"{NS}/drive/state", wire.on_state, 100)
            controller = CellController(NS, context=probe.context)
            executor = probe.executor
            assert executor is not None
            executor.add_node(controller)
            try:
                controller.bring_up()
                answer = controller.call(
                    SetDrive,
                    "set_drive",
                    SetDrive.Request(
                        frequency_hz=F_HZ, amplitude_percent=START_PERCENT, ramp_time_s=0.5
                    ),
                )
                assert answer.result != SetDrive.Response.REFUSED, answer.reason
                assert wait_until(lambda: bool(wire.t), 30.0), "no imu/batch from the simulator"
                assert controller.start(wait_s=30.0)
                yield probe, wire, controller
                passed = True
            finally:
                executor.remove_node(controller)
                controller.destroy_node()
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.send_signal(2)
        for name, process in processes.items():
            try:
                process.wait(timeout=15)
            except Exception:
                process.kill()
                process.wait()
            if not passed:
                print(f"--- {name}:\n{process.output()[-3000:]}")


def _now_s(probe: Any) -> float:
    return float(probe.get_clock().now().nanoseconds) * 1e-9


def _set_amplitude(probe: Any, value: float) -> Any:
    request = SetVibrationAmplitude.Request(amplitude_mps2=value)
    return call(probe, SetVibrationAmplitude, f"{NS}/set_vibration_amplitude", request)


def _set_parameter(probe: Any, node: str, parameter: ParameterMsg) -> None:
    request = SetParameters.Request(parameters=[parameter])
    result = call(probe, SetParameters, f"{NS}/{node}/set_parameters", request).results[0]
    assert result.successful, result.reason


def _settled(wire: Wire, set_point: float, since_s: float, hold_s: float) -> bool:
    """The probe's line within TOLERANCE of the set point over the last ``hold_s``."""
    ends, lines = wire.lines(since_s)
    if ends.size == 0 or ends[-1] - since_s < hold_s:
        return False
    recent = lines[ends >= ends[-1] - hold_s]
    return bool(np.all(np.abs(recent / set_point - 1.0) < TOLERANCE))


@pytest.mark.timeout(180)
def test_regulation_holds_the_line_through_a_live_stiffness_drop(tmp_path: Path) -> None:
    with amplitude_cell(tmp_path) as (probe, wire, _controller):
        # -- open loop at START_PERCENT: the line on the wire, which gives the set point ----------
        assert wait_until(
            lambda: (
                bool(wire.states)
                and (s := wire.last_state()).state == DriveState.STATE_RUNNING
                and s.amplitude_percent == START_PERCENT
            ),
            20.0,
        )
        time.sleep(2.0)  # the carrier settles into its periodic motion
        now = _now_s(probe)
        open_loop = wire.line(now - 1.5, now)
        set_point = SET_POINT_GAIN * open_loop
        state = wire.last_state()
        assert not state.amplitude_regulated
        assert math.isnan(state.amplitude_set_point_mps2)

        # -- before any measurement the reach is unknown: only bad values are refused -----------
        answer = _set_amplitude(probe, math.nan)
        assert answer.result == SetVibrationAmplitude.Response.REFUSED
        assert "nan m/s^2 is not a finite number" in answer.reason, answer.reason
        assert "reach not measured yet" in answer.reason
        assert math.isnan(answer.reachable_max_mps2)

        # -- regulation on, no set point yet: it measures its reach, the drive stays put ---------
        _set_parameter(probe, "drive_interface", _bool("amplitude.enabled", True))
        assert wait_until(lambda: math.isfinite(wire.last_state().measured_amplitude_mps2), 10.0), (
            "the drive interface measured no line"
        )
        beyond = 3.0 * open_loop * MAX_PERCENT / START_PERCENT
        assert wait_until(
            lambda: math.isfinite(_set_amplitude(probe, math.nan).reachable_max_mps2), 10.0
        )
        for value, named in (
            (beyond, f"{beyond:g} m/s^2 beyond the drive's reach"),
            (-1.0, "-1 m/s^2 must be > 0"),
            (math.inf, "inf m/s^2"),
        ):
            answer = _set_amplitude(probe, value)
            assert answer.result == SetVibrationAmplitude.Response.REFUSED
            assert named in answer.reason, answer.reason
            assert "reachable 0 .. " in answer.reason, answer.reason
            # the reach the drive interface measured: the probe's line scaled to the limit
            assert answer.reachable_max_mps2 == pytest.approx(
                open_loop * MAX_PERCENT / START_PERCENT, rel=0.05
            )
        state = wire.last_state()
        assert math.isnan(state.amplitude_set_point_mps2)  # the refusals changed nothing
        assert state.target_amplitude_percent == START_PERCENT
        assert state.amplitude_percent == START_PERCENT

        # -- the set point: the loop moves the drive until the line is there ----------------------
        answer = _set_amplitude(probe, set_point)
        assert answer.result == SetVibrationAmplitude.Response.ACCEPTED, answer.reason
        accepted = _now_s(probe)
        assert wait_until(lambda: _settled(wire, set_point, accepted, 1.5), 15.0), (
            f"the line did not settle at {set_point:.4g} m/s^2: {wire.lines(accepted)[1][-10:]}"
        )
        state = wire.last_state()
        assert state.amplitude_regulated
        assert state.amplitude_set_point_mps2 == pytest.approx(set_point)
        assert state.measured_amplitude_mps2 == pytest.approx(set_point, rel=TOLERANCE)
        settled_percent = state.amplitude_percent
        assert settled_percent > START_PERCENT  # the loop owns the amplitude

        # a refused set point while regulating changes nothing either
        answer = _set_amplitude(probe, math.nan)
        assert answer.result == SetVibrationAmplitude.Response.REFUSED
        assert "nan" in answer.reason
        assert answer.reachable_max_mps2 == pytest.approx(
            set_point * MAX_PERCENT / settled_percent, rel=0.05
        )
        assert wire.last_state().amplitude_set_point_mps2 == pytest.approx(set_point)

        # -- the springs lose 15 % of their stiffness, live ---------------------------------------
        got = call(
            probe,
            GetParameters,
            f"{NS}/platform_simulator/get_parameters",
            GetParameters.Request(names=["youngs_modulus_pa"]),
        )
        modulus = got.values[0].double_value
        assert modulus > 0.0
        dropped = _now_s(probe)
        _set_parameter(probe, "platform_simulator", _double("youngs_modulus_pa", 0.85 * modulus))
        time.sleep(RECOVERY_S + 3.0)

        ends, lines = wire.lines(dropped - 1.0)
        off = np.abs(lines / set_point - 1.0)
        before, after = ends <= dropped, ends > dropped
        assert off[before].max() < TOLERANCE, off[before]  # settled before the drop
        # softer springs raise this carrier's 30 Hz line by 2.2 % in steady state (3-7 % in the
        # transient): it is within 2 % again only because the loop took the amplitude down
        assert off[after].max() > 0.01, "the stiffness drop did not disturb the line"
        assert wire.last_state().amplitude_percent < 0.99 * settled_percent
        misses = ends[after & (off >= TOLERANCE)]
        last_miss = misses.max() if misses.size else dropped
        recovered = ends[after & (ends > last_miss)]  # the final run within tolerance
        assert recovered.size >= 10, f"the line never stayed within 2 % (last miss {last_miss})"
        recovery_s = recovered[0] - dropped if misses.size else 0.0
        print(
            f"line {set_point:.4g} m/s^2: {100 * off[after].max():.1f} % off after the drop, "
            f"within 2 % again {recovery_s:.2f} s after it"
        )
        assert recovery_s <= RECOVERY_S
        with wire.lock:
            amplitudes = [s.amplitude_percent for s in wire.states]
        assert max(amplitudes) <= MAX_PERCENT
