"""The speed monitor node over DDS: alarms raised and cleared in a stall and a starvation."""

from __future__ import annotations

import signal
import sys
import threading
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_test_tools import call, probe_node, running, wait_until

from feeder_ros.msg import DriveCommand, PartSensorEvent, SpeedStatus, VehicleEstimate
from feeder_ros.nodes.stall_detector import MIDDLEWARE_CATCH_UP_S

BIN = Path(sys.executable).parent
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def test_stall_and_starvation_are_raised_and_cleared() -> None:
    ns = "/monitor_alarms"
    command = [
        str(BIN / "speed_monitor"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", "stall_time_s:=1.0", "-p", "starvation_time_s:=2.5", "-p", "publish_rate_hz:=10.0",
        "-p", "target_speed_mps:=0.01",
    ]  # fmt: skip
    with running(command), probe_node() as node:
        statuses: list[SpeedStatus] = []
        diagnostics: list[DiagnosticArray] = []
        node.create_subscription(SpeedStatus, f"{ns}/speed/status", statuses.append, 100)
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 100)
        drive = node.create_publisher(DriveCommand, f"{ns}/drive/command", RELIABLE)
        estimate = node.create_publisher(VehicleEstimate, f"{ns}/estimate", RELIABLE)
        edges = node.create_publisher(PartSensorEvent, f"{ns}/parts/sensor_events", RELIABLE)
        assert wait_until(lambda: bool(statuses), 20.0)
        assert wait_until(lambda: estimate.get_subscription_count() > 0, 10.0)
        speed = {"value": 0.0}
        stop = threading.Event()

        def feed() -> None:  # a drive that is on, and an estimator reporting `speed`
            while not stop.is_set():
                drive.publish(DriveCommand(enabled=True, frequency_hz=20.0, amplitude_n=40.0))
                estimate.publish(
                    VehicleEstimate(mean_speed_mps=speed["value"], mean_speed_confidence=1.0)
                )
                time.sleep(0.05)

        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()
        try:

            def alarm(bit: int) -> bool:
                return bool(statuses) and bool(statuses[-1].alarms & bit)

            # the part does not move: stall (an error)
            assert wait_until(lambda: alarm(SpeedStatus.ALARM_STALL), 10.0)
            assert statuses[-1].level == SpeedStatus.LEVEL_ERROR

            # /diagnostics follows on its own topic: the array of the same tick may still be
            # on its way when the status has arrived
            def own_level() -> bytes | None:
                own = [
                    s
                    for array in diagnostics
                    for s in array.status
                    if s.name == f"{ns}/speed_monitor: part speed"
                ]
                return own[-1].level if own else None

            assert wait_until(lambda: own_level() == DiagnosticStatus.ERROR, 5.0), own_level()
            # a parameter change (new limits) keeps the raised alarm: nothing is hidden
            value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=0.2)
            request = SetParameters.Request(
                parameters=[ParameterMsg(name="speed_tolerance", value=value)]
            )
            answer = call(node, SetParameters, f"{ns}/speed_monitor/set_parameters", request)
            assert answer.results[0].successful, answer.results[0].reason
            after = len(statuses)
            assert wait_until(lambda: len(statuses) >= after + 3, 5.0)
            assert all(s.alarms & SpeedStatus.ALARM_STALL for s in statuses[after:])
            # parts move at the target: the stall clears
            speed["value"] = 0.01
            assert wait_until(lambda: not alarm(SpeedStatus.ALARM_STALL), 5.0)
            assert statuses[-1].estimated_speed_mps == 0.01
            # no part seen since the drive started: starvation (a warning) ...
            assert wait_until(lambda: alarm(SpeedStatus.ALARM_STARVATION), 10.0)
            assert statuses[-1].level == SpeedStatus.LEVEL_WARN
            # ... cleared by the next part at a sensor
            edge = PartSensorEvent(sensor_index=0, part_id=3, present=True)
            edges.publish(edge)
            assert wait_until(lambda: not alarm(SpeedStatus.ALARM_STARVATION), 5.0)
            assert wait_until(lambda: statuses[-1].alarms == 0, 5.0)
            assert statuses[-1].message.startswith("at target (")
        finally:
            stop.set()
            feeder.join(timeout=5)


def test_its_own_stall_is_no_sensor_timeout_but_silence_is() -> None:
    """The monitor process stopped for 2.6 s (longer than sensor_timeout_s, 2 s) while the
    estimator keeps publishing: no sensor timeout on resuming (silence counts from the late
    tick; the estimates sent meanwhile arrive). Estimates that really stop raise it."""
    ns = "/monitor_stall"
    command = [
        str(BIN / "speed_monitor"), "--ros-args", "-r", f"__ns:={ns}",
        "-p", "target_speed_mps:=0.01",
    ]  # fmt: skip
    with running(command) as process, probe_node() as node:
        statuses: list[tuple[float, SpeedStatus]] = []
        diagnostics: list[DiagnosticArray] = []
        node.create_subscription(
            SpeedStatus, f"{ns}/speed/status", lambda m: statuses.append((time.monotonic(), m)), 100
        )
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 100)
        drive = node.create_publisher(DriveCommand, f"{ns}/drive/command", RELIABLE)
        estimate = node.create_publisher(VehicleEstimate, f"{ns}/estimate", RELIABLE)
        assert wait_until(lambda: estimate.get_subscription_count() > 0, 20.0)
        sending = threading.Event()
        sending.set()
        stop = threading.Event()

        def feed() -> None:
            while not stop.is_set():
                drive.publish(DriveCommand(enabled=True, frequency_hz=20.0, amplitude_n=40.0))
                if sending.is_set():
                    estimate.publish(
                        VehicleEstimate(mean_speed_mps=0.01, mean_speed_confidence=1.0)
                    )
                time.sleep(0.05)

        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()
        try:
            assert wait_until(
                lambda: bool(statuses) and statuses[-1][1].message.startswith("at target ("), 15.0
            )
            process.send_signal(signal.SIGSTOP)
            stopped = time.monotonic()
            time.sleep(2.6)
            process.send_signal(signal.SIGCONT)
            # the estimates sent meanwhile may take a moment more (the reliable protocol repairs
            # what the stopped reader missed after a heartbeat): at target again soon after
            assert wait_until(
                lambda: (
                    statuses[-1][0] > stopped + 2.6
                    and statuses[-1][1].message.startswith("at target (")
                    # and a second status since the stop: the first after the resume may be
                    # at target already, and the checks below look at more than one
                    and sum(t > stopped for t, _ in statuses) >= 2
                ),
                10.0,
            )
            assert statuses[-1][0] - stopped < 2.6 + MIDDLEWARE_CATCH_UP_S + 0.5
            after = [m for t, m in statuses if t > stopped]
            assert len(after) >= 2
            # no alarm, no warning; just after resuming the speed may be too old to be "at target"
            assert [m.message for m in after if m.alarms or m.level] == []

            def stalls_seen() -> str | None:  # from the newest /diagnostics array (own topic)
                own = [
                    {v.key: v.value for v in s.values}
                    for array in diagnostics
                    for s in array.status
                    if s.name == f"{ns}/speed_monitor: part speed"
                ]
                return own[-1].get("stalls_seen") if own else None

            assert wait_until(lambda: stalls_seen() == "1", 5.0), stalls_seen()
            # the estimator goes silent (the monitor runs): a sensor timeout within about 2 s
            sending.clear()
            silent = time.monotonic()
            assert wait_until(
                lambda: bool(statuses[-1][1].alarms & SpeedStatus.ALARM_SENSOR_TIMEOUT), 10.0
            )
            assert statuses[-1][1].level == SpeedStatus.LEVEL_ERROR
            # sensor_timeout_s (2 s) after the last estimate, sent up to 0.05 s before `silent`
            assert statuses[-1][0] - silent >= 1.9
        finally:
            stop.set()
            feeder.join(timeout=5)
            process.send_signal(signal.SIGCONT)
