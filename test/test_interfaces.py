"""The generated messages and services: importable, typed as designed, serialisable on the wire."""

from __future__ import annotations

import math

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from feeder_ros.msg import (
    CarrierState,
    DriveCommand,
    DriveState,
    PartExit,
    PartSensorEvent,
    PartState,
    PartStateArray,
    SpeedStatus,
    VehicleEstimate,
)
from feeder_ros.srv import SetDrive, SetTargetSpeed, SpawnParts


def test_measurements_carry_a_header_stamp() -> None:
    for message_type in (
        CarrierState,
        DriveCommand,
        DriveState,
        PartExit,
        PartSensorEvent,
        PartStateArray,
        SpeedStatus,
        VehicleEstimate,
    ):
        fields = message_type.get_fields_and_field_types()
        assert fields["header"] == "std_msgs/Header", message_type.__name__


def test_every_physical_field_names_its_unit() -> None:
    units = ("_m", "_mps", "_mps2", "_hz", "_n", "_s", "_percent", "_ppm")
    unitless = {
        "header", "enabled", "stiffness_branch", "part_id", "phase", "on_track", "parts",
        "sensor_index", "present", "parts_out_total", "status", "status_message", "state",
        "speed_mode", "backend", "fault_reason", "level", "alarms", "message", "slip_fraction",
        "level_state", "pause_reason", "level_sensors", "feed_active", "feed_parts_delivered",
        "amplitude_regulated",
    }  # fmt: skip
    for message_type in (
        CarrierState, DriveCommand, DriveState, PartExit, PartSensorEvent, PartState,
        SpeedStatus, VehicleEstimate,
    ):  # fmt: skip
        for name in message_type.get_fields_and_field_types():
            if name in unitless or name.endswith("_confidence"):
                continue
            assert name.endswith(units), f"{message_type.__name__}.{name} has no unit suffix"


def test_phase_constants_agree_between_messages() -> None:
    for name in ("PHASE_STICK", "PHASE_SLIP_FORWARD", "PHASE_SLIP_BACKWARD"):
        assert getattr(PartState, name) == getattr(VehicleEstimate, name)
    assert (PartState.PHASE_STICK, PartState.PHASE_SLIP_FORWARD) == (0, 1)
    assert PartState.PHASE_SLIP_BACKWARD == 2
    assert (CarrierState.BRANCH_FORWARD, CarrierState.BRANCH_BACKWARD) == (1, -1)


def test_round_trip_through_cdr_keeps_every_value() -> None:
    state = PartStateArray()
    state.header.stamp.sec = 12
    state.header.stamp.nanosec = 345
    state.header.frame_id = "track"
    for part_id in range(3):
        part = PartState()
        part.part_id = part_id
        part.position_m = 0.01 * part_id
        part.velocity_mps = -0.25 + part_id
        part.relative_velocity_mps = 1e-3 * part_id
        part.phase = PartState.PHASE_SLIP_BACKWARD
        part.on_track = part_id != 2
        state.parts.append(part)
    decoded = deserialize_message(serialize_message(state), PartStateArray)
    assert decoded == state
    assert decoded.parts[2].on_track is False
    assert decoded.parts[1].velocity_mps == pytest.approx(0.75)

    estimate = VehicleEstimate(mean_speed_mps=0.042, status=VehicleEstimate.STATUS_GAP)
    estimate.part_velocity_mps = math.nan
    decoded_estimate = deserialize_message(serialize_message(estimate), VehicleEstimate)
    assert math.isnan(decoded_estimate.part_velocity_mps)
    assert decoded_estimate.mean_speed_mps == 0.042
    assert decoded_estimate.status == VehicleEstimate.STATUS_GAP


def test_services_answer_with_a_result_code_and_reason() -> None:
    for service in (SetDrive, SetTargetSpeed):
        response = service.Response()
        assert {"result", "reason"} <= set(response.get_fields_and_field_types())
        assert (service.Response.ACCEPTED, service.Response.CLAMPED) == (0, 1)
        assert service.Response.REFUSED == 2
    request = SpawnParts.Request(count=3, position_m=0.1, spacing_m=0.02)
    assert (request.count, request.position_m, request.spacing_m) == (3, 0.1, 0.02)
