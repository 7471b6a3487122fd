"""The drive interface's speed trim on the wire: it reads the estimator's calibration and holds
each setting for a sensor transit before it steps again, once the transit count has risen past
the first message's (the probe plays the estimator)."""

from __future__ import annotations

import math
import time
from pathlib import Path

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_drive_cell import drive_node, small_speed_table
from ros_test_tools import wait_until

from feeder_ros.msg import DriveState, PartCalibration, VehicleEstimate
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.srv import SetTargetSpeed

LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
HOLD_S = 6.0


def _calibration(transits: int, stamp: object) -> PartCalibration:
    """A calibration at the nominal friction (no table rebuild), ``transits`` transits used."""
    plant = FeederParameters()
    g_kappa = plant.gravity_mps2 * plant.friction_multiplier
    message = PartCalibration(
        state=PartCalibration.STATE_CALIBRATING,
        stick_limit_mps2=plant.static_friction * g_kappa,
        stick_limit_uncertainty=0.3,
        slip_deceleration_mps2=plant.kinetic_friction * g_kappa,
        slip_deceleration_uncertainty=0.1,
        static_friction=plant.static_friction,
        kinetic_friction=plant.kinetic_friction,
        accelerometer_gain=1.0,
        accelerometer_gain_uncertainty=0.03,
        transits_used=transits,
        operating_points=1,
    )
    message.header.stamp = stamp
    return message


def test_the_trim_holds_each_setting_until_a_transit_of_it_is_used(tmp_path: Path) -> None:
    ns = "/drive_trim_hold"
    params = (
        *small_speed_table(tmp_path),
        "max_amplitude_rate_percent_per_s:=100.0",
        "max_frequency_rate_hz_per_s:=100.0",
        "sim_feedback_timeout_s:=0.0",
        f"speed_trim.transit_wait_s:={HOLD_S}",
    )
    with drive_node(ns, *params) as cell:
        probe = cell.probe
        calibration = probe.create_publisher(PartCalibration, f"{ns}/calibration", LATCHED)
        estimates = probe.create_publisher(VehicleEstimate, f"{ns}/estimate", RELIABLE)
        cell.bring_up()
        cell.start_heartbeat()
        refused = cell.set_speed(5.0)
        assert refused.result == SetTargetSpeed.Response.REFUSED
        target = 0.5 * float(refused.reason.rsplit("..", 1)[1].split()[0])
        answer = cell.set_speed(target)
        assert answer.result == SetTargetSpeed.Response.ACCEPTED, answer.reason
        # the first message is the drive's baseline (a restored calibration counts the transits
        # of earlier runs); then a transit used before the start: this cell times transits
        calibration.publish(_calibration(3, probe.get_clock().now().to_msg()))
        time.sleep(0.5)
        calibration.publish(_calibration(4, probe.get_clock().now().to_msg()))
        time.sleep(0.5)

        def estimate() -> None:  # a trusted estimate 10 % slow, whatever the setting
            message = VehicleEstimate(
                mean_speed_mps=0.9 * target,
                mean_speed_uncertainty_mps=0.002 * target,
                window_s=1.0,
                status=VehicleEstimate.STATUS_OK,
            )
            message.header.stamp = probe.get_clock().now().to_msg()
            estimates.publish(message)

        probe.create_timer(0.1, estimate)
        assert cell.trigger("start").success
        running = cell.wait_state(DriveState.STATE_RUNNING)
        t_running = cell.now_s()
        first = running.target_amplitude_percent
        assert math.isclose(first, answer.amplitude_percent, rel_tol=1e-9)

        def stepped_from(amplitude: float) -> bool:
            last = cell.last_state()
            return last is not None and last.target_amplitude_percent > amplitude * 1.001

        # held: no transit of this setting comes, so the step waits out the hold
        assert wait_until(lambda: stepped_from(first), HOLD_S + 6.0)
        t_first_step = cell.now_s()
        assert t_first_step - t_running >= HOLD_S - 1.5, t_first_step - t_running
        notes = [
            kv.value
            for array in list(cell.diagnostics)
            for status in array.status
            for kv in status.values
            if kv.key == "speed trim"
        ]
        assert any("holding the setting for a sensor transit" in note for note in notes), notes
        # a transit of the new setting is used: the next step follows the next estimate
        second = cell.last_state()
        assert second is not None
        time.sleep(0.5)  # the new setting reached (a step of <= 15 % at 100 %/s)
        calibration.publish(_calibration(5, probe.get_clock().now().to_msg()))
        t_transit = cell.now_s()
        assert wait_until(lambda: stepped_from(second.target_amplitude_percent), HOLD_S + 4.0)
        assert cell.now_s() - t_transit < HOLD_S - 2.0, cell.now_s() - t_transit
        assert cell.trigger("stop").success
