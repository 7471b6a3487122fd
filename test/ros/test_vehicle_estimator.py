"""The estimator node over DDS: against the simulator's ground truth, and on bad input."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import (
    DescribeParameters,
    GetParameters,
    SetParameters,
    SetParametersAtomically,
)
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from ros_test_tools import call, probe_node, running, wait_until
from sensor_msgs.msg import Imu

from feeder_ros.msg import CarrierState, DriveCommand, PartStateArray, VehicleEstimate
from feeder_ros.nodes.vehicle_estimator import imu_sample
from feeder_ros.nodes.vehicle_estimator_parameters import DEFAULTS, build_estimator

BIN = Path(sys.executable).parent
CONFIG = Path(__file__).resolve().parents[2] / "config" / "platform_simulator.yaml"
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def _double(name: str, value: float) -> ParameterMsg:
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    )


def _seconds(stamp) -> float:  # type: ignore[no-untyped-def]
    return stamp.sec + stamp.nanosec * 1e-9


def _feeder(stack: ExitStack, ns: str, frequency_hz: float) -> None:
    """Simulator (damped preset) + a drive + the estimator, in namespace ``ns``."""
    stack.enter_context(
        running(
            [
                str(BIN / "platform_simulator"), "--ros-args", "--params-file", str(CONFIG),
                "-r", "__node:=platform_simulator_realistic", "-r", f"__ns:={ns}",
                "-p", "imu_rate_hz:=500.0", "-p", "state_rate_hz:=250.0",
                "-p", "imu_noise_density_mps2_per_sqrt_hz:=0.003", "-p", "imu_bias_mps2:=0.05",
            ]
        )
    )  # fmt: skip
    stack.enter_context(
        running(
            [
                str(BIN / "manual_drive"), "--ros-args", "-r", f"__ns:={ns}",
                "-p", f"frequency_hz:={frequency_hz}", "-p", "amplitude_n:=40.0",
            ]
        )
    )  # fmt: skip
    # the simulator's part is the estimator's nominal part: known as after a calibration
    stack.enter_context(
        running(
            [
                str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}",
                "-p", "calibration.friction_uncertainty:=0.01",
                "-p", "calibration.gain_uncertainty:=0.0",
            ]
        )
    )  # fmt: skip


def _true_speed(parts: list[PartStateArray], t_end_s: float, span_s: float) -> float:
    """Ground-truth mean speed of part 0 over the estimate's own window (simulation time).

    The part's position carries the carrier's vibration (hundreds of um), so the window's ends
    must be the estimate's: positions are interpolated there from the 250 Hz state stream.
    """
    samples = [
        (_seconds(m.header.stamp), m.parts[0].position_m)
        for m in parts
        if m.parts and m.parts[0].on_track
    ]
    t, x = np.array(samples).T
    start = t_end_s - span_s
    assert t[0] <= start, (t[0], start)
    assert t[-1] >= t_end_s, (t[-1], t_end_s)
    x0, x1 = np.interp([start, t_end_s], t, x)
    return float((x1 - x0) / span_s)


def test_namespaced_feeders_side_by_side_estimate_their_own_true_speed() -> None:
    feeders = {"/cell/feeder_a": 20.0, "/cell/feeder_b": 30.0}
    with ExitStack() as stack, probe_node() as node:
        estimates: dict[str, list[VehicleEstimate]] = {ns: [] for ns in feeders}
        parts: dict[str, list[PartStateArray]] = {ns: [] for ns in feeders}
        diagnostics: list[DiagnosticArray] = []
        driven_from = dict.fromkeys(feeders, math.inf)  # first carrier state under the drive

        def note_drive(ns: str, state: CarrierState) -> None:
            # the estimator may hear the drive before the simulator does (discovery order): until
            # the simulator applies it the carrier rests and the part with it (an estimate of 0
            # is right then, but not the drive point this test is about)
            applied = math.isclose(state.drive_frequency_hz, feeders[ns], rel_tol=1e-9) and (
                math.isclose(state.drive_amplitude_n, 40.0, rel_tol=1e-9)
            )
            if applied and math.isinf(driven_from[ns]):
                driven_from[ns] = _seconds(state.header.stamp)

        for ns in feeders:
            node.create_subscription(VehicleEstimate, f"{ns}/estimate", estimates[ns].append, 100)
            node.create_subscription(
                PartStateArray, f"{ns}/parts/state", parts[ns].append, RELIABLE
            )
            node.create_subscription(
                CarrierState, f"{ns}/carrier/state", lambda m, ns=ns: note_drive(ns, m), RELIABLE
            )
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 100)
        for ns, frequency in feeders.items():
            _feeder(stack, ns, frequency)

        def state_span(ns: str) -> tuple[float, float]:
            stamps = [
                _seconds(m.header.stamp) for m in parts[ns] if m.parts and m.parts[0].on_track
            ]
            return (stamps[0], stamps[-1]) if stamps else (math.inf, -math.inf)

        def judged(ns: str) -> list[VehicleEstimate]:
            """The estimates the truth can judge: vouched for by the estimator (status OK,
            confident; after a sample gap on a loaded machine it restarts its statistics and says
            so), with their window inside the received part states (the probe's subscription
            starts late; either stream may run a few samples ahead) and under the applied drive."""
            first, last = state_span(ns)
            first = max(first, driven_from[ns])
            return [
                e
                for e in estimates[ns]
                if e.status == VehicleEstimate.STATUS_OK
                and e.mean_speed_confidence > 0.8
                and first <= _seconds(e.header.stamp) - e.window_s
                and _seconds(e.header.stamp) <= last
            ]

        def recent(ns: str) -> list[tuple[float, int, float, float, str]]:
            return [
                (_seconds(e.header.stamp), e.status, round(e.mean_speed_confidence, 3),
                 e.window_s, e.status_message)
                for e in estimates[ns][-8:]
            ]  # fmt: skip

        assert wait_until(lambda: all(judged(ns) for ns in feeders), 60.0), (
            driven_from,
            {ns: recent(ns) for ns in feeders},
        )
        time.sleep(3.0)  # a full estimator window (2 s) more of steady state
        speeds = {}
        for ns in feeders:
            last = judged(ns)[-1]
            truth = _true_speed(parts[ns], _seconds(last.header.stamp), last.window_s)
            speeds[ns] = last.mean_speed_mps
            assert last.mean_speed_mps == pytest.approx(truth, rel=0.05), (
                ns,
                truth,
                _seconds(last.header.stamp),
                last.window_s,
                last.mean_speed_confidence,
                recent(ns),
            )
            assert 0.0 <= last.slip_fraction <= 1.0
            assert last.phase in (0, 1, 2)
            assert math.isfinite(last.advance_per_cycle_m)
        # the two feeders run at different drive points, so their speeds differ clearly
        assert speeds["/cell/feeder_a"] > 2.0 * speeds["/cell/feeder_b"] > 0.0
        names = {s.name for array in diagnostics for s in array.status}
        for ns in feeders:
            assert f"{ns}/vehicle_estimator: estimate" in names


def test_bad_samples_are_reported_not_averaged_in() -> None:
    ns = "/estimator_input"
    # the sensor subscription is best effort unless overridden: reliable here, so that every
    # sample the test sends arrives (the counts below are exact)
    command = [
        str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", f"qos_overrides.{ns}/imu.subscription.reliability:=reliable",
        "-p", "startup_timeout_s:=4.0",
    ]  # fmt: skip
    # the probe first: it subscribes while the node process still starts up (the start-up WARNs
    # last startup_timeout_s from the node's start; discovery under load can take much of that)
    with probe_node() as node, running(command):
        estimates: list[VehicleEstimate] = []
        diagnostics: list[DiagnosticArray] = []
        node.create_subscription(VehicleEstimate, f"{ns}/estimate", estimates.append, 100)
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 100)
        imu = node.create_publisher(Imu, f"{ns}/imu", RELIABLE)
        drive = node.create_publisher(DriveCommand, f"{ns}/drive/command", 10)
        assert wait_until(lambda: imu.get_subscription_count() > 0, 20.0)
        assert wait_until(lambda: drive.get_subscription_count() > 0, 20.0)
        readers = node.get_subscriptions_info_by_topic(f"{ns}/imu")
        assert [r.qos_profile.reliability for r in readers] == [ReliabilityPolicy.RELIABLE]

        def own_status() -> DiagnosticStatus | None:
            for array in reversed(diagnostics):
                for status in array.status:
                    if status.name == f"{ns}/vehicle_estimator: estimate":
                        return status
            return None

        # no first sample: waiting (WARN) while within startup_timeout_s (4 s here), although
        # that is longer than input_timeout_s (1 s); after it, a sensor error
        def missing_sensor() -> bool:
            status = own_status()
            return status is not None and status.level == DiagnosticStatus.ERROR

        assert wait_until(missing_sensor, 15.0)
        seen = [
            (s.level, s.message)
            for array in diagnostics
            for s in array.status
            if s.name == f"{ns}/vehicle_estimator: estimate"
        ]
        first_error = next(
            i for i, (level, _) in enumerate(seen) if level == DiagnosticStatus.ERROR
        )
        waiting = seen[:first_error]
        assert waiting, seen
        for level, text in waiting:
            assert level == DiagnosticStatus.WARN, seen
            assert text.startswith("waiting for the first accelerometer sample ("), seen
        assert max(float(text.split("(")[1].split()[0]) for _, text in waiting) > 1.0, seen
        error = seen[first_error][1]
        assert error.startswith("no accelerometer sample in ")
        assert error.endswith(" since start")
        assert float(error.split()[4]) >= 4.0  # printed to 0.1 s

        t0 = 1000.0
        command = DriveCommand(enabled=True, frequency_hz=25.0, amplitude_n=40.0)
        command.header.stamp.sec = int(t0)
        drive.publish(command)

        def send(t: float, value: float) -> None:
            message = Imu()
            message.header.stamp.sec = int(t)
            message.header.stamp.nanosec = round((t - int(t)) * 1e9)
            message.linear_acceleration.x = value
            imu.publish(message)

        rate = 500.0
        for k in range(int(2.0 * rate)):
            t = t0 + k / rate
            value = 3.0 * math.sin(2 * math.pi * 25.0 * t)
            if k in (701, 702, 703):
                value = math.nan
            send(t, value)
            if k % 10 == 0:
                time.sleep(0.01)  # paced (~1 kHz): the reader's history holds 500 samples

        def reported(code: int) -> bool:
            return any(e.status == code for e in estimates)

        # the node processes what arrived by each publish tick as one batch; the drops are
        # counted over the window, so however a tick splits the three NaNs, the count reaches 3
        invalid = VehicleEstimate.STATUS_INVALID_SAMPLES
        three = "3 non-finite or out-of-range samples dropped;"
        assert wait_until(
            lambda: any(
                e.status == invalid and e.status_message.startswith(three) for e in estimates
            ),
            10.0,
        ), [(e.status, e.status_message) for e in estimates[-5:]]
        counts = [int(e.status_message.split()[0]) for e in estimates if e.status == invalid]
        assert max(counts) == 3, counts
        bad = next(
            e for e in estimates if e.status == invalid and e.status_message.startswith(three)
        )
        # the only gap is the one the three dropped samples left (from k = 700 to 704)
        assert "; gap of 0.008 s at t=1001.400000;" in bad.status_message, bad.status_message
        for estimate in estimates:
            assert not (math.isnan(estimate.mean_speed_mps) and estimate.mean_speed_confidence > 0)

        # stamps going backwards are dropped and reported
        for k in range(20):
            send(t0 + 0.5 + k / rate, 0.0)
        assert wait_until(lambda: reported(VehicleEstimate.STATUS_OUT_OF_ORDER), 10.0)


def test_drive_frequency_band_is_declared_and_min_below_max_is_enforced() -> None:
    ns = "/estimator_band"
    base = f"{ns}/vehicle_estimator"
    command = [str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}"]
    names = ["min_drive_frequency_hz", "max_drive_frequency_hz"]
    with running(command), probe_node() as node:
        descriptors = call(
            node, DescribeParameters, f"{base}/describe_parameters",
            DescribeParameters.Request(names=names),
        ).descriptors  # fmt: skip
        assert [d.name for d in descriptors] == names
        for descriptor in descriptors:
            assert descriptor.type == ParameterType.PARAMETER_DOUBLE
            assert not descriptor.read_only  # applied live: the estimator restarts
            assert "search band when no drive command is received [Hz]" in descriptor.description
            [bounds] = descriptor.floating_point_range
            assert (bounds.from_value, bounds.to_value) == (0.1, 10000.0)

        def get() -> list[float]:
            values = call(
                node, GetParameters, f"{base}/get_parameters", GetParameters.Request(names=names)
            ).values
            return [v.double_value for v in values]

        assert get() == [2.0, 300.0]  # the estimator core's default band

        def set_one(name: str, value: float) -> Any:
            request = SetParameters.Request(parameters=[_double(name, value)])
            return call(node, SetParameters, f"{base}/set_parameters", request).results[0]

        # one end changed alone is checked against the other end in force
        refused = set_one("min_drive_frequency_hz", 400.0)
        assert not refused.successful
        assert refused.reason == (
            "min_drive_frequency_hz=400 Hz must be below max_drive_frequency_hz=300 Hz"
        )
        refused = set_one("max_drive_frequency_hz", 2.0)
        assert not refused.successful
        assert "min_drive_frequency_hz=2 Hz must be below max_drive_frequency_hz=2 Hz" in (
            refused.reason
        )
        assert not set_one("min_drive_frequency_hz", 0.0).successful  # below the range
        assert get() == [2.0, 300.0]

        # both ends at once (the drive's range), then one end against the new other end
        band = SetParametersAtomically.Request(
            parameters=[_double(names[0], 20.0), _double(names[1], 60.0)]
        )
        answer = call(node, SetParametersAtomically, f"{base}/set_parameters_atomically", band)
        assert answer.result.successful, answer.result.reason
        assert get() == [20.0, 60.0]
        refused = set_one("min_drive_frequency_hz", 60.0)
        assert not refused.successful
        assert "min_drive_frequency_hz=60 Hz must be below max_drive_frequency_hz=60 Hz" in (
            refused.reason
        )
        accepted = set_one("max_drive_frequency_hz", 45.0)
        assert accepted.successful, accepted.reason
        assert get() == [20.0, 45.0]


def test_the_band_parameters_become_the_estimators_search_band() -> None:
    values = {**DEFAULTS, "min_drive_frequency_hz": 20.0, "max_drive_frequency_hz": 60.0}
    assert build_estimator(values).config.frequency_band_hz == (20.0, 60.0)
    assert build_estimator(dict(DEFAULTS)).config.frequency_band_hz == (2.0, 300.0)


def test_node_refuses_to_start_with_min_not_below_max() -> None:
    result = subprocess.run(
        [
            str(BIN / "vehicle_estimator"), "--ros-args", "-r", "__ns:=/estimator_bad_band",
            "-p", "min_drive_frequency_hz:=60.0", "-p", "max_drive_frequency_hz:=20.0",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )  # fmt: skip
    assert result.returncode == 2
    assert "min_drive_frequency_hz=60 Hz must be below max_drive_frequency_hz=20 Hz" in (
        result.stdout + result.stderr
    )


@pytest.mark.parametrize("frame_id", ["", "a", "carrier_imu", "x" * 13, "ümlaut"])
def test_imu_fields_are_read_straight_from_the_cdr_bytes(frame_id: str) -> None:
    message = Imu()
    message.header.frame_id = frame_id
    message.header.stamp.sec = 1_795_300_000
    message.header.stamp.nanosec = 123_456_789
    message.orientation.w = 7.0  # fields before the acceleration must be skipped, not read
    message.angular_velocity_covariance[8] = -1.0
    message.linear_acceleration.x = 0.123456789
    message.linear_acceleration.y = -2.5
    message.linear_acceleration.z = math.nan
    stamp, (x, y, z) = imu_sample(serialize_message(message))
    assert stamp == pytest.approx(1_795_300_000.123456789, abs=1e-6)
    assert (x, y) == (0.123456789, -2.5)
    assert math.isnan(z)


def test_malformed_imu_bytes_are_refused_with_the_reason() -> None:
    data = serialize_message(Imu())
    with pytest.raises(ValueError, match="truncated Imu message"):
        imu_sample(data[:240])  # cut inside linear_acceleration
    with pytest.raises(ValueError, match="not a CDR message"):
        imu_sample(b"\x07\x07" + data[2:])


def test_a_parameter_change_keeps_the_drive_command_in_force() -> None:
    """A live parameter change rebuilds the estimator; the drive command received before stays in
    force (without it the new estimator would search the band and could take a subharmonic)."""
    import rclpy
    from rclpy.parameter import Parameter

    from feeder_ros.nodes.vehicle_estimator import VehicleEstimatorNode

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = VehicleEstimatorNode(context=context)
        try:
            assert math.isnan(node._estimator.drive_frequency_hz)
            command = DriveCommand(enabled=True, frequency_hz=31.0, amplitude_n=10.0)
            command.header.stamp.sec = 5
            node._on_command(command)
            assert node._estimator.drive_frequency_hz == 31.0
            [result] = node.set_parameters([Parameter("window_s", value=3.0)])
            assert result.successful, result.reason
            assert node._estimator.config.window_s == 3.0  # a new estimator ...
            assert node._estimator.drive_frequency_hz == 31.0  # ... with the drive in force
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_the_calibration_worker_ends_before_the_node_is_destroyed() -> None:
    """Its worker publishes each update; one finishing while the node shuts down must not
    publish on the destroyed node (a traceback at every such stop)."""
    import rclpy

    from feeder_ros.nodes.vehicle_estimator import VehicleEstimatorNode

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = VehicleEstimatorNode(context=context)
        calibration = node._calibration
        assert calibration.worker is not None
        assert calibration.worker.is_alive()
        node.destroy_node()
        calibration.worker.join(timeout=5.0)
        assert not calibration.worker.is_alive()
        calibration._publish()  # an update that finished meanwhile: nothing to publish on
    finally:
        rclpy.shutdown(context=context)


def _carrier_imu(t: float) -> Imu:
    """An accelerometer sample at ``t`` [s] of a carrier vibrating at 25 Hz, 3 m/s^2."""
    message = Imu()
    message.header.stamp.sec = int(t)
    message.header.stamp.nanosec = round((t - int(t)) * 1e9)
    message.linear_acceleration.x = 3.0 * math.sin(2 * math.pi * 25.0 * t)
    return message


def test_its_own_stall_is_no_sensor_timeout_but_silence_is() -> None:
    """The estimator process stopped for 2.6 s (input_timeout_s is 1 s) while the accelerometer
    keeps sending: no sensor timeout once it runs again. Samples that really stop raise it."""
    ns = "/estimator_stall"
    command = [
        str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", f"qos_overrides.{ns}/imu.subscription.reliability:=reliable",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        seen: list[tuple[float, int, str, dict[str, str]]] = []

        def on_diagnostics(array: DiagnosticArray) -> None:
            for s in array.status:
                if s.name == f"{ns}/vehicle_estimator: estimate":
                    values = {v.key: v.value for v in s.values}
                    seen.append((time.monotonic(), s.level[0], s.message, values))

        node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 100)
        imu = node.create_publisher(Imu, f"{ns}/imu", RELIABLE)
        assert wait_until(lambda: imu.get_subscription_count() > 0, 20.0)
        sending = threading.Event()
        sending.set()
        stop = threading.Event()

        def feed() -> None:  # 200 Hz, in bursts of 10 samples every 50 ms
            k = 0
            while not stop.is_set():
                for _ in range(10 if sending.is_set() else 0):
                    imu.publish(_carrier_imu(1000.0 + k / 200.0))
                    k += 1
                time.sleep(0.05)

        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()
        try:
            assert wait_until(lambda: bool(seen) and int(seen[-1][3]["samples_received"]) > 0, 15.0)
            process.send_signal(signal.SIGSTOP)
            stopped = time.monotonic()
            time.sleep(2.6)
            process.send_signal(signal.SIGCONT)
            assert wait_until(lambda: seen[-1][0] > stopped + 6.0, 15.0)
            after = [(level, text) for t, level, text, _ in seen if t > stopped]
            assert len(after) >= 3
            assert [text for level, text in after if level == DiagnosticStatus.ERROR[0]] == []
            assert seen[-1][3]["stalls_seen"] == "1"
            # the accelerometer goes silent while the estimator runs: a sensor timeout
            sending.clear()
            assert wait_until(lambda: seen[-1][2].startswith("sensor timeout: "), 10.0)
            assert seen[-1][1] == DiagnosticStatus.ERROR[0]
        finally:
            stop.set()
            feeder.join(timeout=5)
            process.send_signal(signal.SIGCONT)


def test_estimates_keep_their_rate_while_the_drive_repeats_its_command() -> None:
    """A drive re-sends its set point at 50 Hz, each right after a burst of samples here: the
    estimate still goes out at its publish rate (20 Hz), not only when a timer tick happens to
    find samples the command callback left it."""
    ns = "/estimator_repeated_command"
    command = [
        str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", f"qos_overrides.{ns}/imu.subscription.reliability:=reliable",
    ]  # fmt: skip
    with running(command), probe_node() as node:
        received: list[float] = []
        node.create_subscription(
            VehicleEstimate, f"{ns}/estimate", lambda m: received.append(time.monotonic()), 100
        )
        imu = node.create_publisher(Imu, f"{ns}/imu", RELIABLE)
        drive = node.create_publisher(DriveCommand, f"{ns}/drive/command", RELIABLE)
        assert wait_until(
            lambda: imu.get_subscription_count() > 0 and drive.get_subscription_count() > 0, 20.0
        )
        stop = threading.Event()

        def feed() -> None:  # 500 Hz in bursts of 10 samples, each burst then the command
            k = 0
            while not stop.is_set():
                for _ in range(10):
                    imu.publish(_carrier_imu(1000.0 + k / 500.0))
                    k += 1
                again = DriveCommand(enabled=True, frequency_hz=25.0, amplitude_n=10.0)
                again.header.stamp.sec = 1000
                drive.publish(again)
                time.sleep(0.02)

        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()
        try:
            assert wait_until(lambda: bool(received), 15.0)
            start, count = time.monotonic(), len(received)
            time.sleep(4.0)
            rate = (len(received) - count) / (time.monotonic() - start)
        finally:
            stop.set()
            feeder.join(timeout=5)
        assert rate >= 0.75 * DEFAULTS["publish_rate_hz"], f"{rate:.1f} estimates/s"
