"""The estimator's online calibration over DDS: transits from the simulator's part-present sensors
calibrate the part model of a plant that is not the nominal one; the calibration is published
(latched), written to its file and read back by a restarted node; an operator's speed and a reset
go through services; a corrupt file and impossible inputs are refused with the reason."""

from __future__ import annotations

import math
import sys
from contextlib import ExitStack
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_test_tools import call, probe_node, running, wait_until
from std_srvs.srv import Trigger

from feeder_ros.estimation.calibration_file import read_calibration
from feeder_ros.estimation.stick_slip_observer import PartModel
from feeder_ros.msg import PartCalibration
from feeder_ros.srv import SetMeasuredSpeed

BIN = Path(sys.executable).parent
CONFIG = Path(__file__).resolve().parents[2] / "config" / "platform_simulator.yaml"
NS = "/calibration_cell"
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
SENSORS = "0.05, 0.135"


def _plant(stack: ExitStack) -> None:
    """The damped feeder with its part's friction off the nominal 0.2 / 0.1, driven steadily
    (22 Hz, 40 N: about 30 mm/s, a transit every feed interval)."""
    stack.enter_context(
        running(
            [
                str(BIN / "platform_simulator"), "--ros-args", "--params-file", str(CONFIG),
                "-r", "__node:=platform_simulator_realistic", "-r", f"__ns:={NS}",
                "-p", "static_friction:=0.24", "-p", "kinetic_friction:=0.09",
                "-p", "imu_rate_hz:=1000.0", "-p", "state_rate_hz:=100.0",
                "-p", "initial_parts:=4", "-p", "part_spacing_m:=0.03",
                "-p", "feed_interval_s:=1.0", "-p", "track_length_m:=0.2",
                "-p", f"sensor_positions_m:={SENSORS}",
            ]
        )
    )  # fmt: skip
    stack.enter_context(
        running(
            [
                str(BIN / "manual_drive"), "--ros-args", "-r", f"__ns:={NS}",
                "-p", "frequency_hz:=22.0", "-p", "amplitude_n:=40.0",
            ]
        )
    )  # fmt: skip


def _estimator(calibration_file: Path) -> list[str]:
    return [
        str(BIN / "vehicle_estimator"), "--ros-args", "-r", f"__ns:={NS}",
        "-p", f"calibration.sensor_positions_m:={SENSORS}",
        "-p", f"calibration.file:={calibration_file}",
    ]  # fmt: skip


def _part_model_status(diagnostics: list[DiagnosticArray]) -> DiagnosticStatus | None:
    for array in reversed(diagnostics):
        for status in array.status:
            if status.name == f"{NS}/vehicle_estimator: part model":
                return status
    return None


def test_transits_calibrate_publish_persist_and_survive_a_restart(tmp_path: Path) -> None:
    calibration_file = tmp_path / "part_calibration.yaml"
    with ExitStack() as stack, probe_node() as node:
        received: list[PartCalibration] = []
        node.create_subscription(PartCalibration, f"{NS}/calibration", received.append, LATCHED)
        _plant(stack)
        with running(_estimator(calibration_file)):
            assert wait_until(lambda: bool(received), 30.0)
            assert received[0].state == PartCalibration.STATE_NOMINAL
            assert received[0].static_friction == 0.2
            assert math.isclose(received[0].stick_limit_uncertainty, 0.3)

            def calibrated() -> bool:
                return bool(received) and received[-1].transits_used >= 3

            assert wait_until(calibrated, 90.0), [m.message for m in received[-5:]]
            last = received[-1]
            assert last.state == PartCalibration.STATE_CALIBRATING  # one operating point
            assert last.operating_points == 1
            # one point fixes a combination of the friction: the slip deceleration moved to the
            # plant's, and its uncertainty shrank well below the prior's 30 %
            assert last.slip_deceleration_uncertainty < 0.2
            stored = read_calibration(calibration_file, PartModel())
            assert stored is not None
            assert stored.transits >= 3

            # an operator's speed that is not a number: refused with the reason, nothing changes
            answer = call(
                node,
                SetMeasuredSpeed,
                f"{NS}/calibration/measured_speed",
                SetMeasuredSpeed.Request(speed_mps=math.nan, uncertainty_mps=0.0),
            )
            assert not answer.accepted
            assert "speed_mps=nan is not a finite number" in answer.reason
        # a restarted estimator reads the file and publishes it (latched) at once
        received.clear()
        with running(_estimator(calibration_file)):
            assert wait_until(lambda: bool(received), 30.0)
            assert received[0].transits_used >= stored.transits
            assert received[0].state != PartCalibration.STATE_NOMINAL
            answer = call(node, Trigger, f"{NS}/calibration/reset", Trigger.Request())
            assert answer.success
            assert wait_until(lambda: received[-1].state == PartCalibration.STATE_NOMINAL, 10.0)
            assert received[-1].transits_used == 0
            reset = read_calibration(calibration_file, PartModel())
            assert reset is not None
            assert reset.transits == 0


def test_a_corrupt_calibration_file_is_reported_and_the_nominal_part_used(tmp_path: Path) -> None:
    calibration_file = tmp_path / "part_calibration.yaml"
    calibration_file.write_text("format: [unterminated\n")
    with probe_node() as node:
        received: list[PartCalibration] = []
        diagnostics: list[DiagnosticArray] = []
        node.create_subscription(PartCalibration, f"{NS}/calibration", received.append, LATCHED)
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 100)
        with running(_estimator(calibration_file)) as estimator:

            def warned() -> bool:
                status = _part_model_status(diagnostics)
                return status is not None and status.level == DiagnosticStatus.WARN

            assert wait_until(warned, 30.0)
            status = _part_model_status(diagnostics)
            assert status is not None
            assert status.message.startswith(f"{calibration_file}: not YAML")
            assert status.message.endswith("running on the nominal part")
            assert wait_until(lambda: bool(received), 10.0)
            assert received[-1].state == PartCalibration.STATE_NOMINAL
            assert estimator.poll() is None  # the node runs on
        assert calibration_file.read_text() == "format: [unterminated\n"  # left for inspection
