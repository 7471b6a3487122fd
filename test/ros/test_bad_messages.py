"""Nodes over DDS keep running through malformed or impossible input, and say what they ignored.

Each node here is a real process; ``running`` insists that it is still alive at the end and exits
cleanly on Ctrl-C (a node that died of a callback's exception fails the test there).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_test_tools import probe_node, running, wait_until

from feeder_ros.msg import (
    AccelerometerBatch,
    CarrierState,
    DriveCommand,
    DriveState,
    SpeedStatus,
    VehicleEstimate,
)
from feeder_ros.physics.parameters import FeederParameters

BIN = Path(sys.executable).parent
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
BEST_EFFORT = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)


def _simulation_status(arrays: list[DiagnosticArray], ns: str) -> list[DiagnosticStatus]:
    name = f"{ns}/platform_simulator: simulation"
    return [s for array in arrays for s in array.status if s.name == name]


def test_simulator_ignores_bad_commands_and_recovers_from_a_solver_failure() -> None:
    ns = "/bad_commands"
    undamped = FeederParameters(damping_ns_per_m=0.0)
    command = [
        str(BIN / "platform_simulator"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", "damping_ns_per_m:=0.0", "-p", "command_timeout_s:=1.0",
        "-p", "state_rate_hz:=100.0", "-p", "imu_rate_hz:=100.0",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        states: list[CarrierState] = []
        diagnostics: list[DiagnosticArray] = []
        node.create_subscription(CarrierState, f"{ns}/carrier/state", states.append, RELIABLE)
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 100)
        publisher = node.create_publisher(DriveCommand, f"{ns}/drive/command", RELIABLE)
        assert wait_until(lambda: len(states) > 10, 20.0), process.poll()
        assert wait_until(lambda: publisher.get_subscription_count() > 0, 10.0)

        def send(future_s: float = 0.0, **fields: object) -> None:
            message = DriveCommand(**fields)
            stamp = node.get_clock().now().nanoseconds + int(future_s * 1e9)
            message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp, 10**9)
            publisher.publish(message)

        def amplitude() -> float:
            return states[-1].drive_amplitude_n if states else math.nan

        send(enabled=True, frequency_hz=25.0, amplitude_n=40.0)
        assert wait_until(lambda: amplitude() == 40.0, 10.0), amplitude()
        # malformed: a stop with a negative ramp, an absurd force, a ramp of a thousand years
        send(enabled=False, frequency_hz=25.0, amplitude_n=0.0, ramp_time_s=-1.0)
        send(enabled=True, frequency_hz=25.0, amplitude_n=1e300)
        send(enabled=True, frequency_hz=25.0, amplitude_n=10.0, ramp_time_s=3e10)
        # a stop stamped an hour ahead: ignored, so the timeout still ends the 40 N drive
        send(future_s=3600.0, enabled=False, frequency_hz=25.0, amplitude_n=0.0)
        count = len(states)
        assert wait_until(lambda: len(states) > count + 20, 10.0)
        assert {s.drive_amplitude_n for s in states[count:]} <= {40.0, 0.0}
        assert wait_until(lambda: amplitude() == 0.0, 5.0), "the command timeout did not act"
        log = process.output()
        # (the same warning again within 5 s is throttled: the absurd force is not logged)
        assert "ignoring malformed drive command: enabled=False" in log, log[-2000:]
        assert "ramp_time_s=-1.0 (finite, >= 0)" in log, log[-2000:]
        assert "ramp_s=30000000000.0 must be <= 1e+09" in log, log[-2000:]
        assert "s ahead of the simulation clock" in log, log[-2000:]
        assert process.poll() is None

        # an undamped branch driven exactly at its natural frequency has no bounded closed form:
        # the simulation restarts at rest, and /diagnostics says why
        resonance = undamped.forward_natural_frequency_hz
        send(enabled=True, frequency_hz=resonance, amplitude_n=1.0)

        def failed() -> bool:
            own = _simulation_status(diagnostics, ns)
            return bool(own) and own[-1].level == DiagnosticStatus.ERROR

        assert wait_until(failed, 10.0), [s.message for s in _simulation_status(diagnostics, ns)]
        assert "simulation failed" in _simulation_status(diagnostics, ns)[-1].message
        assert "exact resonance" in process.output()
        assert process.poll() is None

        # driven again (off resonance): running, and the error clears
        def driven_again() -> bool:
            send(enabled=True, frequency_hz=25.0, amplitude_n=20.0)
            return amplitude() == 20.0

        assert wait_until(driven_again, 10.0), amplitude()
        assert wait_until(
            lambda: _simulation_status(diagnostics, ns)[-1].level == DiagnosticStatus.OK, 5.0
        )


def test_monitor_and_estimator_ignore_impossible_values() -> None:
    ns = "/bad_values"
    monitor = [
        str(BIN / "speed_monitor"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", "publish_rate_hz:=10.0",
    ]  # fmt: skip
    estimator = [str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}"]
    with (
        running(monitor) as monitor_process,
        running(estimator) as estimator_process,
        probe_node() as node,
    ):
        statuses: list[SpeedStatus] = []
        estimates: list[VehicleEstimate] = []
        node.create_subscription(SpeedStatus, f"{ns}/speed/status", statuses.append, 100)
        node.create_subscription(VehicleEstimate, f"{ns}/estimate", estimates.append, 100)
        drive = node.create_publisher(DriveState, f"{ns}/drive/state", RELIABLE)
        batches = node.create_publisher(AccelerometerBatch, f"{ns}/imu/batch", BEST_EFFORT)
        assert wait_until(lambda: bool(statuses), 20.0), monitor_process.poll()
        assert wait_until(lambda: drive.get_subscription_count() > 0, 10.0)
        assert wait_until(lambda: batches.get_subscription_count() > 0, 20.0)
        # the monitor: a target speed of inf in speed mode
        drive.publish(
            DriveState(
                state=DriveState.STATE_RUNNING,
                amplitude_percent=10.0,
                speed_mode=True,
                target_speed_mps=math.inf,
            )
        )

        # the estimator: absurd sample periods (one in ns sent as seconds), resent until the
        # best-effort stream delivers one and the estimator names it
        def send_bad_batches() -> bool:
            for period in (1e300, 1e6, math.inf):
                batch = AccelerometerBatch(sample_period_s=period)
                batch.header.stamp = node.get_clock().now().to_msg()
                batch.acceleration_x_mps2 = [0.0] * 500
                batches.publish(batch)
            return "sample_period_s=1e+300 (0 < period <= 1 s)" in estimator_process.output()

        assert wait_until(send_bad_batches, 20.0), estimator_process.output()[-2000:]
        time.sleep(1.0)
        count = len(statuses)
        assert wait_until(lambda: len(statuses) >= count + 5, 5.0), "the monitor went silent"
        assert monitor_process.poll() is None
        assert wait_until(
            lambda: "target_speed_mps=inf is not finite" in monitor_process.output(), 10.0
        ), monitor_process.output()[-2000:]
        # refused, not processed: nothing estimated from them, and each one named
        assert not estimates
        assert estimator_process.poll() is None
