"""The platform simulator as a real process over DDS: drive in, IMU and state out, parameters."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from ros_test_tools import call, probe_node, running, wait_until
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

from feeder_ros.msg import CarrierState, DriveCommand, PartStateArray
from feeder_ros.nodes.simulator_services import spawn_refusal
from feeder_ros.srv import SpawnParts

SIMULATOR = str(Path(sys.executable).parent / "platform_simulator")
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
BEST_EFFORT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)


def _double(name: str, value: float) -> ParameterMsg:
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    )


def test_drive_command_makes_the_carrier_vibrate_at_the_drive_frequency() -> None:
    ns = "/sim_drive"
    command = [
        SIMULATOR, "--ros-args", "-r", f"__ns:={ns}",
        "-p", "damping_ns_per_m:=200.0", "-p", "imu_noise_density_mps2_per_sqrt_hz:=0.002",
        "-p", "imu_rate_hz:=500.0", "-p", "state_rate_hz:=250.0",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        imu: list[Imu] = []
        states: list[CarrierState] = []
        node.create_subscription(Imu, f"{ns}/imu", imu.append, BEST_EFFORT)
        node.create_subscription(CarrierState, f"{ns}/carrier/state", states.append, RELIABLE)
        publisher = node.create_publisher(DriveCommand, f"{ns}/drive/command", 10)

        assert wait_until(lambda: len(imu) > 50, 20.0), process.poll()

        sent: list[int] = []  # command stamps [ns]

        def command() -> None:
            message = DriveCommand(enabled=True, frequency_hz=31.0, amplitude_n=40.0)
            message.header.stamp = node.get_clock().now().to_msg()
            publisher.publish(message)
            sent.append(Time.from_msg(message.header.stamp).nanoseconds)

        def driven() -> bool:
            command()
            return bool(states) and states[-1].drive_amplitude_n == 40.0

        assert wait_until(driven, 10.0), "the drive command never took effect"
        start = time.monotonic()
        while time.monotonic() - start < 3.0:  # settle and record, refreshing the command
            command()
            time.sleep(0.05)
        # the state as the commands stopped: the simulator's command timeout stops the drive
        # while the checks below run (the probe keeps receiving)
        held = len(states)
        as_stopped = states[held - 1]
        stamps = np.array([Time.from_msg(m.header.stamp).nanoseconds for m in imu])
        steps = np.diff(stamps)
        assert np.all(steps > 0), "IMU stamps not strictly increasing"
        assert np.all(steps % 2_000_000 == 0), "IMU samples off the 500 Hz grid"
        # best effort: a busy probe may drop some (the reliable state stream below may not), but
        # what arrives is on the grid; the spectrum is taken over the longest gapless stretch
        on = next(s for s in states if s.drive_amplitude_n == 40.0)  # the drive took effect
        driven_from = Time.from_msg(on.header.stamp).nanoseconds + 200_000_000
        samples = [m for m in imu if Time.from_msg(m.header.stamp).nanoseconds >= driven_from]
        gaps = np.diff([Time.from_msg(m.header.stamp).nanoseconds for m in samples])
        breaks = np.flatnonzero(gaps != 2_000_000)
        edges = np.concatenate(([-1], breaks, [gaps.size]))
        longest = int(np.argmax(np.diff(edges)))
        first, stop = edges[longest] + 1, edges[longest + 1] + 1
        stretch = [m.linear_acceleration.x for m in samples[first:stop]][-1000:]
        assert len(stretch) >= 500, f"no gapless second of IMU samples (breaks at {breaks})"
        state_stamps = np.array([Time.from_msg(m.header.stamp).nanoseconds for m in states])
        assert np.all(np.diff(state_stamps) == 4_000_000), "state samples skipped or duplicated"

        x = np.array(stretch)
        assert np.ptp(x) > 1.0, "carrier does not respond to the drive"
        spectrum = np.abs(np.fft.rfft(x - x.mean()))
        peak_hz = np.fft.rfftfreq(x.size, 2e-3)[np.argmax(spectrum)]
        assert abs(peak_hz - 31.0) <= 1.0, peak_hz
        assert abs(np.mean([m.linear_acceleration.z for m in imu]) - 9.81) < 0.05

        assert as_stopped.drive_frequency_hz == 31.0
        assert as_stopped.drive_amplitude_n == 40.0
        assert as_stopped.stiffness_branch in (
            CarrierState.BRANCH_FORWARD,
            CarrierState.BRANCH_BACKWARD,
        )
        branches = {s.stiffness_branch for s in states[:held][-500:]}
        assert branches == {1, -1}, "the carrier should switch stiffness every cycle"

        # commands stop: a command older than command_timeout_s (1 s, on the simulation clock,
        # whose stamps are the states') is a stop. Judged by stamps, not by the wall clock: on a
        # loaded machine the simulation may run behind the wall clock.
        last = sent[-1]

        def stamp(m: CarrierState) -> int:
            return int(Time.from_msg(m.header.stamp).nanoseconds)

        assert wait_until(lambda: stamp(states[-1]) > last + 1_500_000_000, 30.0), "no progress"
        before = [s.drive_amplitude_n for s in states if stamp(s) <= last]
        after = [s.drive_amplitude_n for s in states if stamp(s) > last + 1_250_000_000]
        assert before[-1] == 40.0, "driven up to the last command"
        assert after, "no states after the timeout"
        assert set(after) == {0.0}, "stale command was not treated as stop"
    assert process.returncode == 0


def test_parameters_are_validated_and_applied_live() -> None:
    ns = "/sim_params"
    with running([SIMULATOR, "--ros-args", "-r", f"__ns:={ns}"]), probe_node() as node:
        name = f"{ns}/platform_simulator/set_parameters"
        refused = call(
            node, SetParameters, name,
            SetParameters.Request(parameters=[_double("static_friction", 0.05)]),
        ).results[0]  # fmt: skip
        assert not refused.successful
        assert "kinetic_friction=0.1 must not exceed static_friction=0.05" in refused.reason
        refused = call(
            node, SetParameters, name,
            SetParameters.Request(parameters=[_double("damping_ns_per_m", float("nan"))]),
        ).results[0]  # fmt: skip
        assert not refused.successful
        assert "damping_ns_per_m" in refused.reason
        read_only = call(
            node, SetParameters, name,
            SetParameters.Request(parameters=[_double("imu_rate_hz", 200.0)]),
        ).results[0]  # fmt: skip
        assert not read_only.successful
        accepted = call(
            node, SetParameters, name,
            SetParameters.Request(parameters=[_double("static_friction", 0.3)]),
        ).results[0]  # fmt: skip
        assert accepted.successful, accepted.reason
        values = call(
            node, GetParameters, f"{ns}/platform_simulator/get_parameters",
            GetParameters.Request(names=["static_friction", "kinetic_friction"]),
        ).values  # fmt: skip
        assert [v.double_value for v in values] == [0.3, 0.1]


def test_a_spawn_request_is_refused_naming_each_bad_value() -> None:
    assert spawn_refusal(3, 0.1, 0.05, 0.5, "track_length_m") == ""
    assert spawn_refusal(0, 0.1, 0.05, 0.5, "x") == "count=0 must be in 1..10000"
    assert spawn_refusal(10001, 0.1, 0.0, 0.5, "x") == "count=10001 must be in 1..10000"
    both = spawn_refusal(1, math.nan, -0.1, 0.5, "x")
    assert both == (
        "position_m=nan must be a finite value >= 0; spacing_m=-0.1 must be a finite value >= 0"
    )
    # the last part at 0.1 + 2 * 0.2 = 0.5 m: on the end is off the track
    assert spawn_refusal(3, 0.1, 0.2, 0.5, "track_length_m") == (
        "parts from 0.1 m spaced 0.2 m do not fit on the track (track_length_m: 0.5 m)"
    )
    assert "(the tail of the queue: 0.3 m)" in spawn_refusal(
        3, 0.1, 0.1, 0.3, "the tail of the queue"
    )


def test_spawn_and_reset_services_and_part_states() -> None:
    ns = "/sim_parts"
    with running([SIMULATOR, "--ros-args", "-r", f"__ns:={ns}"]), probe_node() as node:
        parts: list[PartStateArray] = []
        node.create_subscription(PartStateArray, f"{ns}/parts/state", parts.append, RELIABLE)
        base = f"{ns}/platform_simulator"
        # refused requests change nothing: sent again if a reply is lost in discovery (CI lost
        # this first one's: "failed to send response (timeout)")
        zero = SpawnParts.Request(count=0)
        bad = call(node, SpawnParts, f"{base}/spawn_parts", zero, repeatable=True)
        assert not bad.success
        assert "count=0" in bad.message
        too_far = SpawnParts.Request(count=3, position_m=0.49, spacing_m=0.1)
        assert not call(node, SpawnParts, f"{base}/spawn_parts", too_far, repeatable=True).success
        good = SpawnParts.Request(count=3, position_m=0.1, spacing_m=0.05)
        answer = call(node, SpawnParts, f"{base}/spawn_parts", good)
        assert answer.success, answer.message
        assert list(answer.part_ids) == [1, 2, 3]

        def four_parts() -> bool:
            return bool(parts) and len(parts[-1].parts) == 4

        assert wait_until(four_parts, 10.0)
        positions = [p.position_m for p in parts[-1].parts]
        assert np.allclose(positions, [0.0, 0.1, 0.15, 0.2], atol=1e-6)
        assert all(p.phase == p.PHASE_STICK for p in parts[-1].parts)

        reset = call(node, Trigger, f"{base}/reset", Trigger.Request())
        assert reset.success
        parts.clear()

        def one_part() -> bool:
            return bool(parts) and len(parts[-1].parts) == 1

        assert wait_until(one_part, 10.0)


def test_sim_time_mode_publishes_clock_faster_than_real_time() -> None:
    ns = "/sim_clock"
    command = [
        SIMULATOR, "--ros-args", "-r", f"__ns:={ns}", "-p", "use_sim_time:=true",
        "-p", "real_time_factor:=0.0", "-p", "max_step_s:=0.2", "-p", "imu_rate_hz:=200.0",
        "-p", "state_rate_hz:=100.0",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        clocks: list[ClockMessage] = []
        node.create_subscription(ClockMessage, "/clock", clocks.append, 100)
        assert wait_until(lambda: len(clocks) > 2, 20.0)
        wall_start, sim_start = time.monotonic(), Time.from_msg(clocks[-1].clock).nanoseconds
        time.sleep(2.0)
        wall = time.monotonic() - wall_start
        simulated = (Time.from_msg(clocks[-1].clock).nanoseconds - sim_start) * 1e-9
        assert simulated / wall > 5.0, f"only {simulated / wall:.1f}x real time"
        times = [Time.from_msg(c.clock).nanoseconds for c in clocks]
        assert times == sorted(times)
    assert process.returncode == 0


def test_a_paced_factor_above_max_step_over_tick_is_reached() -> None:
    """10x real time with the default tick (10 ms) and step (50 ms): several steps per tick (one
    step per tick capped the pace at 5x)."""
    ns = "/sim_paced"
    command = [
        SIMULATOR, "--ros-args", "-r", f"__ns:={ns}", "-p", "use_sim_time:=true",
        "-p", "real_time_factor:=10.0", "-p", "imu_rate_hz:=100.0", "-p", "state_rate_hz:=50.0",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        clocks: list[ClockMessage] = []
        node.create_subscription(ClockMessage, "/clock", clocks.append, 1000)
        assert wait_until(lambda: len(clocks) > 20, 20.0)
        time.sleep(0.5)
        wall_start, sim_start = time.monotonic(), Time.from_msg(clocks[-1].clock).nanoseconds
        time.sleep(3.0)
        wall = time.monotonic() - wall_start
        simulated = (Time.from_msg(clocks[-1].clock).nanoseconds - sim_start) * 1e-9
        assert 8.0 < simulated / wall < 12.0, f"{simulated / wall:.2f}x real time, asked 10x"
    assert process.returncode == 0


def test_a_part_that_left_is_listed_once_more_then_no_longer() -> None:
    """parts/state carries the parts on the track and each exited part once (on_track false):
    the message does not grow with every part ever fed."""
    ns = "/sim_exits"
    command = [
        SIMULATOR, "--ros-args", "-r", f"__ns:={ns}", "-p", "track_length_m:=0.02",
        "-p", "initial_parts:=3", "-p", "part_start_m:=0.017", "-p", "part_spacing_m:=0.001",
        "-p", "damping_ns_per_m:=200.0",
    ]  # fmt: skip
    with running(command), probe_node() as node:
        parts: list[PartStateArray] = []
        node.create_subscription(PartStateArray, f"{ns}/parts/state", parts.append, RELIABLE)
        publisher = node.create_publisher(DriveCommand, f"{ns}/drive/command", 10)

        def drive_until_empty() -> bool:
            message = DriveCommand(enabled=True, frequency_hz=30.0, amplitude_n=40.0)
            message.header.stamp = node.get_clock().now().to_msg()
            publisher.publish(message)
            return len(parts) > 10 and all(len(m.parts) == 0 for m in parts[-5:])

        assert wait_until(drive_until_empty, 30.0), parts[-1] if parts else None
        left = [(m, p) for m in parts for p in m.parts if not p.on_track]
        assert sorted(p.part_id for _, p in left) == [0, 1, 2]  # each exited part once
        for message, part in left:
            later = parts[parts.index(message) + 1 :]
            assert all(part.part_id not in {q.part_id for q in m.parts} for m in later)
