"""Parameters of the vehicle estimator node (ROS-free: docs and tests read them without ROS).

The nominal part (the physics' friction, groove and gravity), the estimator's windows, inputs and
timeouts, and its online calibration's (``calibration.*``); the node's declared interface
(:data:`INTERFACE`); the check of a parameter set as a whole (:func:`check_combination`), and the
estimator and transit pairing a set describes (:func:`build_estimator`,
:func:`measurement_source`).
"""

from __future__ import annotations

import math
from typing import Any

from feeder_ros.estimation.online_calibration import MeasurementSource
from feeder_ros.estimation.part_belief import PartBelief
from feeder_ros.estimation.stick_slip_observer import PartModel
from feeder_ros.estimation.vehicle_estimator import EstimatorConfig, VehicleEstimator
from feeder_ros.node_interfaces import NodeInterface, ServiceSpec, TopicSpec
from feeder_ros.physics.parameters import (
    PARAMETER_SPECS,
    FeederParameters,
    ParameterError,
    ParameterSpec,
)

CALIBRATION_PARAMETERS: dict[str, ParameterSpec] = {
    spec.name: spec
    for spec in (
        ParameterSpec(
            "calibration.enabled",
            bool,
            "",
            "calibrate the part model online from sensor transits and operator speeds",
            read_only=True,
        ),
        ParameterSpec(
            "calibration.file",
            str,
            "",
            "calibration YAML read at start and rewritten (atomically) on every update; empty: "
            "none (the calibration is lost on restart)",
            read_only=True,
        ),
        ParameterSpec(
            "calibration.friction_uncertainty",
            float,
            "1",
            "relative standard uncertainty of the uncalibrated friction (stick limit and slip "
            "deceleration)",
            0.0,
            2.0,
            read_only=True,
        ),
        ParameterSpec(
            "calibration.gain_uncertainty",
            float,
            "1",
            "relative standard uncertainty of the accelerometer's gain",
            0.0,
            0.5,
            read_only=True,
        ),
        ParameterSpec(
            "calibration.sensor_positions_m",
            str,
            "m",
            "track positions of the part-present sensors by index, as 'a, b, ...' (the "
            "simulator's sensor_positions_m); empty: no transit calibration",
            read_only=True,
        ),
        ParameterSpec(
            "calibration.transit_sensors",
            str,
            "",
            "the two sensors whose rising edges are timed, as 'first, second'",
            read_only=True,
        ),
        ParameterSpec(
            "calibration.transit_uncertainty",
            float,
            "1",
            "relative standard uncertainty of one transit speed besides its timing (part to part, "
            "sensor jitter)",
            0.0,
            1.0,
            exclusive_minimum=True,
            read_only=True,
        ),
    )
}
CALIBRATION_DEFAULTS: dict[str, Any] = {
    "calibration.enabled": True,
    "calibration.file": "",
    "calibration.friction_uncertainty": 0.3,
    "calibration.gain_uncertainty": 0.03,
    "calibration.sensor_positions_m": "",
    "calibration.transit_sensors": "0, 1",
    "calibration.transit_uncertainty": 0.01,
}
CALIBRATION_PUBLISHES = (
    TopicSpec(
        "calibration",
        "feeder_ros/msg/PartCalibration",
        "reliable, transient local, depth 1",
        "the part model in use (stick limit, slip deceleration, gain), its uncertainty and the "
        "measurements behind it; on every change",
    ),
)
CALIBRATION_SUBSCRIBES = (
    TopicSpec(
        "parts/sensor_events",
        "feeder_ros/msg/PartSensorEvent",
        "reliable, depth 100",
        "part-present sensor edges: transits between calibration.transit_sensors calibrate the "
        "part model",
    ),
)
CALIBRATION_SERVICES = (
    ServiceSpec(
        "calibration/measured_speed",
        "feeder_ros/srv/SetMeasuredSpeed",
        "an operator's measured part speed at the current drive setting: accepted into the "
        "calibration, or refused with the reason",
    ),
    ServiceSpec(
        "calibration/reset", "std_srvs/srv/Trigger", "forget the calibration: the nominal part"
    ),
)


def _numbers(name: str, text: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.replace(",", " ").split())
    except ValueError:
        raise ParameterError(f"{name}={text!r} is not a list of numbers") from None


def measurement_source(values: dict[str, Any]) -> MeasurementSource:
    """The transit pairing the parameters describe (raises ParameterError naming a bad one)."""
    positions = _numbers("calibration.sensor_positions_m", values["calibration.sensor_positions_m"])
    pair = _numbers("calibration.transit_sensors", values["calibration.transit_sensors"])
    if len(pair) != 2 or any(p != int(p) for p in pair):
        raise ParameterError(
            f"calibration.transit_sensors={values['calibration.transit_sensors']!r} must be two "
            "sensor indices"
        )
    return MeasurementSource(
        positions, (int(pair[0]), int(pair[1])), values["calibration.transit_uncertainty"]
    )


AXES = ("x", "y", "z")
_PART_PARAMETERS = ("static_friction", "kinetic_friction", "groove_angle_deg", "gravity_mps2")
PARAMETERS: dict[str, ParameterSpec] = {
    **{name: PARAMETER_SPECS[name] for name in _PART_PARAMETERS},
    **{
        spec.name: spec
        for spec in (
            ParameterSpec(
                "window_s", float, "s", "window of the mean speed and slip fraction", 0.05, 600.0
            ),
            ParameterSpec(
                "fit_window_s", float, "s", "window of the periodic carrier fit", 0.05, 60.0
            ),
            ParameterSpec(
                "max_harmonic_hz", float, "Hz", "highest harmonic of the carrier fit", 1.0, 1e4
            ),
            ParameterSpec(
                "max_bridge_s", float, "s", "gaps up to this long are bridged by the model", 0.0
            ),
            # the band the drive line is sought in without a drive command: a carrier answering
            # at a subharmonic (period of 2-4 drive periods) has its strongest line below the
            # drive frequency, so the band should be the drive's range (live: a change restarts
            # the estimator, as the window parameters do)
            ParameterSpec(
                "min_drive_frequency_hz",
                float,
                "Hz",
                "lower end of the drive frequency search band when no drive command is received",
                0.1,
                10000.0,
            ),
            ParameterSpec(
                "max_drive_frequency_hz",
                float,
                "Hz",
                "upper end of the drive frequency search band when no drive command is received",
                0.1,
                10000.0,
            ),
            ParameterSpec(
                "publish_rate_hz", float, "Hz", "estimate publish rate", 0.5, 200.0, read_only=True
            ),
            ParameterSpec(
                "imu_axis",
                str,
                "",
                "accelerometer axis along the track",
                choices=AXES,
                read_only=True,
            ),
            ParameterSpec(
                "use_carrier_state",
                bool,
                "",
                "estimate from a displacement sensor (carrier/state) instead of the accelerometer",
                read_only=True,
            ),
            ParameterSpec(
                "input_timeout_s",
                float,
                "s",
                "no sample for this long once samples came is a sensor timeout (diagnostics ERROR)",
                minimum=0.0,
                exclusive_minimum=True,
            ),
            # bring-up is not a steady stream: the sensor's node or driver may start seconds
            # after this one (a cell's processes load at once; the simulator loads its solver)
            ParameterSpec(
                "startup_timeout_s",
                float,
                "s",
                "no first sample this long after the start is a sensor error (diagnostics "
                "ERROR; WARN while waiting)",
                minimum=0.0,
                exclusive_minimum=True,
            ),
        )
    },
    **CALIBRATION_PARAMETERS,
}
DEFAULTS: dict[str, Any] = {
    **{name: getattr(FeederParameters(), name) for name in _PART_PARAMETERS},
    "window_s": 2.0,
    "fit_window_s": 1.0,
    "max_harmonic_hz": 450.0,
    "max_bridge_s": 0.25,
    "min_drive_frequency_hz": EstimatorConfig.frequency_band_hz[0],
    "max_drive_frequency_hz": EstimatorConfig.frequency_band_hz[1],
    "publish_rate_hz": 20.0,
    "imu_axis": "x",
    "use_carrier_state": False,
    "input_timeout_s": 1.0,
    "startup_timeout_s": 10.0,
    **CALIBRATION_DEFAULTS,
}

INTERFACE = NodeInterface(
    executable="vehicle_estimator",
    node_name="vehicle_estimator",
    summary="estimates a nominal part's speed and stick/slip phase from the carrier accelerometer",
    publishes=(
        TopicSpec(
            "estimate",
            "feeder_ros/msg/VehicleEstimate",
            "reliable, depth 10",
            "part velocity and mean speed with their standard uncertainties (mean speed NaN while "
            "SETTLING), phase, advance per cycle, slip fraction, confidences",
        ),
        TopicSpec(
            "/diagnostics",
            "diagnostic_msgs/msg/DiagnosticArray",
            "reliable, depth 10",
            "estimator status at 1 Hz (input gaps, invalid samples, timeouts) and the "
            "calibration's (file problems, refused measurements)",
        ),
        *CALIBRATION_PUBLISHES,
    ),
    subscribes=(
        TopicSpec(
            "imu",
            "sensor_msgs/msg/Imu",
            "sensor data, depth 500 (qos_overrides: reliability, history, depth)",
            "carrier accelerometer",
        ),
        TopicSpec(
            "imu/batch",
            "feeder_ros/msg/AccelerometerBatch",
            "sensor data, depth 500 (qos_overrides: reliability, history, depth)",
            "the same as batches (high-rate sensors)",
        ),
        TopicSpec(
            "drive/command",
            "feeder_ros/msg/DriveCommand",
            "reliable, depth 10",
            "drive frequency (optional; estimated from the spectrum without it)",
        ),
        TopicSpec(
            "carrier/state",
            "feeder_ros/msg/CarrierState",
            "reliable, depth 1000",
            "carrier displacement, used when use_carrier_state is true",
        ),
        *CALIBRATION_SUBSCRIBES,
    ),
    services=CALIBRATION_SERVICES,
    parameters=PARAMETERS,
)


def check_combination(values: dict[str, Any]) -> None:
    """Raises ParameterError naming a value that is bad with the others (the band, an
    estimator or transit pairing that cannot be built)."""
    low, high = values["min_drive_frequency_hz"], values["max_drive_frequency_hz"]
    if low >= high:
        raise ParameterError(
            f"min_drive_frequency_hz={low:g} Hz must be below max_drive_frequency_hz={high:g} Hz"
        )
    build_estimator(values)
    measurement_source(values)


def nominal_part(values: dict[str, Any]) -> PartModel:
    """The configured part (friction, groove, gravity) the estimator starts from."""
    kappa = 1.0 / math.sin(math.radians(values["groove_angle_deg"]) / 2.0)
    return PartModel(
        values["static_friction"], values["kinetic_friction"], kappa, values["gravity_mps2"]
    )


def build_estimator(values: dict[str, Any], belief: PartBelief | None = None) -> VehicleEstimator:
    """A fresh estimator for these parameter values (raises ParameterError naming a bad one),
    running ``belief`` (default: the nominal part with the stated uncertainties)."""
    part = nominal_part(values)
    fit_window = values["fit_window_s"]
    config = EstimatorConfig(
        part=part,
        window_s=values["window_s"],
        fit_window_s=fit_window,
        min_fit_s=min(0.3, fit_window),
        max_harmonic_hz=values["max_harmonic_hz"],
        max_bridge_s=values["max_bridge_s"],
        frequency_band_hz=(values["min_drive_frequency_hz"], values["max_drive_frequency_hz"]),
        batch_interval_s=0.0,  # the node already batches per publish period
        friction_uncertainty=values["calibration.friction_uncertainty"],
        gain_uncertainty=values["calibration.gain_uncertainty"],
    )
    return VehicleEstimator(config, belief)
