"""The drive interface's parameters (ROS free): declarations with units and ranges, defaults, the
conversions of a parameter dict into the cores' settings (limits, Modbus, plant, tracker, level
control, amplitude regulation), and the node's declared interface (topics, services, the action).
(About 840 lines, most of them the declaration table, one entry per parameter with its unit,
range and description: split, the table would only move, and the docs read it as one.)

:mod:`feeder_ros.nodes.drive_interface` declares them on the node; tests, docs and the cell
description read them from here without starting ROS.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from feeder_ros.drive.amplitude_regulator import AmplitudeSettings
from feeder_ros.drive.level_control import LevelSettings
from feeder_ros.drive.limits import DriveLimits, parse_bands
from feeder_ros.drive.modbus import ModbusSettings, RegisterMap
from feeder_ros.drive.resonance_tracker import TrackerSettings
from feeder_ros.drive.speed_model_source import SpeedModelSource
from feeder_ros.node_interfaces import NodeInterface, ServiceSpec, TopicSpec
from feeder_ros.physics.parameters import PARAMETER_SPECS, FeederParameters, ParameterSpec

_AT_CONFIGURE = " (read at configure)"
PLANT_PREFIX = "plant."
_PLANT_EXCLUDED = {"drive_frequency_hz", "drive_amplitude_n"}  # the drive is what we choose

LIMIT_PARAMETERS = (
    ParameterSpec("min_frequency_hz", float, "Hz", "lowest drive frequency", 0.1, 10000.0),
    ParameterSpec("max_frequency_hz", float, "Hz", "highest drive frequency", 0.1, 10000.0),
    ParameterSpec(
        "max_amplitude_percent",
        float,
        "%",
        "highest drive amplitude",
        0.0,
        100.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "max_frequency_rate_hz_per_s",
        float,
        "Hz/s",
        "soft start/stop: fastest frequency change while driving",
        0.0,
        100000.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "max_amplitude_rate_percent_per_s",
        float,
        "%/s",
        "soft start/stop: fastest amplitude change",
        0.0,
        100000.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "forbidden_bands_hz",
        str,
        "Hz",
        "frequency bands a set point may not lie in (ramps cross them), as "
        "'low, high, low, high, ...'; empty: none",
    ),
    ParameterSpec(
        "full_scale_force_n",
        float,
        "N",
        "drive force at 100 % amplitude (force = amplitude/100 * full scale)",
        0.0,
        1.0e6,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "heartbeat_timeout_s",
        float,
        "s",
        "without a heartbeat for this long the drive ramps to zero and faults; "
        "0 disables the watchdog",
        0.0,
        3600.0,
    ),
)
NODE_PARAMETERS = (
    ParameterSpec(
        "backend", str, "", "drive backend" + _AT_CONFIGURE, choices=("sim", "modbus_tcp")
    ),
    ParameterSpec(
        "sim_feedback_timeout_s",
        float,
        "s",
        "sim backend: a simulator silent on parts/state this long after it was live is lost "
        "(latched fault, output off); longer than the simulator's parts/state period; 0: off"
        + _AT_CONFIGURE,
        0.0,
        3600.0,
    ),
    ParameterSpec(
        "publish_rate_hz",
        float,
        "Hz",
        "output, drive/command and drive/state rate" + _AT_CONFIGURE,
        1.0,
        1000.0,
    ),
    ParameterSpec(
        "diagnostics_period_s", float, "s", "/diagnostics period", 0.05, 60.0, read_only=True
    ),
    ParameterSpec(
        "speed_model_enabled",
        bool,
        "",
        "build the physics speed table (target-speed mode)" + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "speed_model_frequency_steps",
        int,
        "1",
        "speed table: frequencies over the allowed range (an identified model: over its band)"
        + _AT_CONFIGURE,
        1,
        1000,
    ),
    ParameterSpec(
        "speed_model_amplitude_steps",
        int,
        "1",
        "speed table: amplitudes from 0 to max_amplitude_percent" + _AT_CONFIGURE,
        2,
        1000,
    ),
    ParameterSpec(
        "speed_model_duration_s",
        float,
        "s",
        "speed table: simulated time per point (one part from rest)" + _AT_CONFIGURE,
        0.0,
        600.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "speed_model_cache_dir",
        str,
        "",
        "directory of cached speed tables (keyed by every input); empty: "
        "$XDG_CACHE_HOME/feeder_ros/speed_tables" + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "speed_model_file",
        str,
        "",
        "identified speed model (YAML from `feeder identify --model-out`) used instead of the "
        "simulated table; empty: the table" + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "unreachable_speed",
        str,
        "",
        "an unreachable target speed is refused (with the reachable range) or clamped "
        "to the nearest reachable one",
        choices=("refuse", "clamp"),
    ),
    ParameterSpec("modbus.host", str, "", "feeder controller address" + _AT_CONFIGURE),
    ParameterSpec("modbus.port", int, "1", "Modbus TCP port" + _AT_CONFIGURE, 1, 65535),
    ParameterSpec("modbus.device_id", int, "1", "Modbus unit/device id" + _AT_CONFIGURE, 0, 255),
    ParameterSpec("modbus.timeout_s", float, "s", "request timeout" + _AT_CONFIGURE, 0.01, 60.0),
    ParameterSpec(
        "modbus.poll_period_s", float, "s", "write/read cycle" + _AT_CONFIGURE, 0.005, 10.0
    ),
    ParameterSpec(
        "modbus.reconnect_min_s", float, "s", "first reconnect delay" + _AT_CONFIGURE, 0.01, 600.0
    ),
    ParameterSpec(
        "modbus.command_timeout_s",
        float,
        "s",
        "the I/O thread switches the drive off when the node has handed over no output for this "
        "long (a hung node never leaves a stale command standing)" + _AT_CONFIGURE,
        0.01,
        60.0,
    ),
    ParameterSpec(
        "modbus.reconnect_max_s",
        float,
        "s",
        "reconnect delay cap (doubling back-off)" + _AT_CONFIGURE,
        0.01,
        600.0,
    ),
    *(
        ParameterSpec(f"modbus.register.{name}", int, "1", f"{meaning} holding register", 0, 65535)
        for name, meaning in (
            ("command", "command word (bit 0 enable, bit 1 alarm reset)"),
            ("frequency", "frequency set point"),
            ("amplitude", "amplitude set point"),
            ("ramp_time", "ramp time to the set point"),
            ("heartbeat", "heartbeat counter (incremented each write)"),
            ("status", "status word (running, alarm bits)"),
            ("alarm_code", "controller alarm code"),
            ("actual_frequency", "actual frequency"),
            ("actual_amplitude", "actual amplitude"),
        )
    ),
    ParameterSpec(
        "modbus.scale.frequency_counts_per_hz",
        float,
        "1/Hz",
        "frequency register counts per Hz",
        0.0,
        1.0e6,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "modbus.scale.amplitude_counts_per_percent",
        float,
        "1/%",
        "amplitude register counts per %",
        0.0,
        1.0e6,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "modbus.scale.ramp_time_counts_per_s",
        float,
        "1/s",
        "ramp-time register counts per s",
        0.0,
        1.0e6,
        exclusive_minimum=True,
    ),
    ParameterSpec("modbus.status_running_bit", int, "1", "status word bit: running", 0, 15),
    ParameterSpec("modbus.status_alarm_bit", int, "1", "status word bit: alarm", 0, 15),
)
_TRACKING = "resonance tracking: "
TRACKING_PARAMETERS = (
    ParameterSpec(
        "tracking.enabled",
        bool,
        "",
        _TRACKING + "in target-speed mode, keep the frequency on the measured part-speed peak "
        "and trim the amplitude to the target speed (applies at once)",
    ),
    ParameterSpec(
        "tracking.feedback_topic",
        str,
        "",
        _TRACKING + "part-speed feedback topic (relative: the feeder's namespace)" + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "tracking.feedback_type",
        str,
        "",
        _TRACKING + "its type: feeder_ros/VehicleEstimate (mean_speed_mps, confidence-gated) or "
        "feeder_ros/SpeedStatus (estimated_speed_mps)" + _AT_CONFIGURE,
        choices=("vehicle_estimate", "speed_status"),
    ),
    ParameterSpec(
        "tracking.min_confidence",
        float,
        "1",
        _TRACKING + "VehicleEstimate readings below this mean_speed_confidence are ignored",
        0.0,
        1.0,
    ),
    ParameterSpec(
        "tracking.feedback_timeout_s",
        float,
        "s",
        _TRACKING + "no valid speed reading this long (by its stamp): hold the centre frequency "
        "and amplitude, WARN",
        0.0,
        600.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "tracking.dither_hz",
        float,
        "Hz",
        _TRACKING + "frequency offset of each half-period from the centre",
        0.0,
        100.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "tracking.dither_period_s",
        float,
        "s",
        _TRACKING + "one dither cycle (a half-period on each side); centre and amplitude move "
        "once per cycle",
        0.0,
        3600.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "tracking.settle_s",
        float,
        "s",
        _TRACKING + "discarded at the start of each half-period (drive transient, speed source "
        "settling); < dither_period_s/2",
        0.0,
        1800.0,
    ),
    ParameterSpec(
        "tracking.gain_hz2",
        float,
        "Hz^2",
        _TRACKING + "centre step per unit relative speed gradient, (dv/df)/target in 1/Hz",
        0.0,
        1000.0,
    ),
    ParameterSpec(
        "tracking.max_step_hz",
        float,
        "Hz",
        _TRACKING + "largest centre frequency step per cycle",
        0.0,
        100.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "tracking.amplitude_kp_percent",
        float,
        "%",
        _TRACKING + "amplitude trim, proportional: % per unit change of the relative speed error",
        0.0,
        1000.0,
    ),
    ParameterSpec(
        "tracking.amplitude_ki_percent",
        float,
        "%",
        _TRACKING + "amplitude trim, integral: % per cycle per unit relative speed error",
        0.0,
        1000.0,
    ),
    ParameterSpec(
        "tracking.max_amplitude_step_percent",
        float,
        "%",
        _TRACKING + "largest amplitude change per cycle",
        0.0,
        100.0,
        exclusive_minimum=True,
    ),
)
SPEED_FEEDBACK_PARAMETERS = (
    ParameterSpec(
        "calibration_topic",
        str,
        "",
        "the estimator's part calibration (feeder_ros/PartCalibration, latched): the physics "
        "speed table follows the calibrated friction; empty: the configured friction"
        + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "speed_trim.enabled",
        bool,
        "",
        "target-speed mode: trim the amplitude on the estimate once it is trustworthy (below "
        "speed_trim.max_uncertainty of the target)",
    ),
    ParameterSpec(
        "speed_trim.estimate_topic",
        str,
        "",
        "the estimate the trim reads (feeder_ros/VehicleEstimate)" + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "speed_trim.gain",
        float,
        "1",
        "speed trim: fraction of the relative speed error corrected per step (through the "
        "speed model's sensitivity of speed to amplitude)",
        0.0,
        2.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "speed_trim.max_step",
        float,
        "1",
        "speed trim: largest relative amplitude change per step",
        0.0,
        2.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "speed_trim.max_uncertainty",
        float,
        "1",
        "speed trim: estimates with a standard uncertainty above this fraction of the target "
        "are not used",
        0.0,
        2.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "speed_trim.transit_wait_s",
        float,
        "s",
        "speed trim: once the calibration (calibration_topic) uses sensor transits, hold each "
        "setting until a transit of it is used, at most this long; 0: never hold",
        0.0,
        600.0,
    ),
)
_LEVEL = "track level control: "
FEEDING_PARAMETERS = (
    ParameterSpec(
        "part_sensor_count",
        int,
        "1",
        "part-present sensors on the track, indices 0..n-1 on parts/sensor_events (the "
        "simulator's sensor_positions_m, or the real feeder's wiring)" + _AT_CONFIGURE,
        1,
        64,
    ),
    ParameterSpec(
        "level.mode",
        str,
        "",
        _LEVEL + "off; one_sensor (full_sensor covered off_delay_s: pause, free on_delay_s: "
        "resume); two_sensors (full_sensor covered: pause, low_sensor free: resume)"
        + _AT_CONFIGURE,
        choices=("off", "one_sensor", "two_sensors"),
    ),
    ParameterSpec(
        "level.full_sensor_index",
        int,
        "1",
        _LEVEL + "the sensor that says the track is full" + _AT_CONFIGURE,
        0,
        63,
    ),
    ParameterSpec(
        "level.low_sensor_index",
        int,
        "1",
        _LEVEL + "two_sensors: the sensor that says the track needs parts" + _AT_CONFIGURE,
        0,
        63,
    ),
    ParameterSpec(
        "level.off_delay_s",
        float,
        "s",
        _LEVEL + "the full sensor covered this long pauses feeding" + _AT_CONFIGURE,
        0.0,
        3600.0,
    ),
    ParameterSpec(
        "level.on_delay_s",
        float,
        "s",
        _LEVEL + "the resume sensor free this long resumes feeding" + _AT_CONFIGURE,
        0.0,
        3600.0,
    ),
    ParameterSpec(
        "level.sensor_timeout_s",
        float,
        "s",
        _LEVEL + "while feeding, no edge on a watched sensor this long: latched fault (sensor "
        "or feed broken); 0: off" + _AT_CONFIGURE,
        0.0,
        86400.0,
    ),
    ParameterSpec(
        "feed.starvation_timeout_s",
        float,
        "s",
        "feed_parts: no part delivered this long while feeding ends the goal (STARVED), unless "
        "the goal sets its own",
        0.0,
        3600.0,
        exclusive_minimum=True,
    ),
    ParameterSpec(
        "feed.feedback_period_s",
        float,
        "s",
        "feed_parts: feedback at least this often (and at every delivered part)",
        0.05,
        60.0,
    ),
)
ENABLED, SET_POINT = "amplitude.enabled", "amplitude.set_point_mps2"
_A = "vibration-amplitude regulation: "
AMPLITUDE_PARAMETERS = (
    ParameterSpec(
        ENABLED,
        bool,
        "",
        _A + "scale the output amplitude (from the set point) to hold the accelerometer's "
        "drive-frequency line: at amplitude.set_point_mps2, or in target-speed mode at the line "
        "the speed loops' amplitude gave at takeover; without a set point it only measures "
        "(applies at once)",
    ),
    ParameterSpec(
        SET_POINT,
        float,
        "m/s^2",
        _A + "the line to hold outside target-speed mode (NaN: none); set_vibration_amplitude "
        "sets it; refused beyond the measured reach and in target-speed mode",
        minimum=0.0,
        exclusive_minimum=True,
        nan_allowed=True,
    ),
    ParameterSpec(
        "amplitude.imu_topic",
        str,
        "",
        _A + "the carrier's accelerometer (relative: the feeder's namespace)" + _AT_CONFIGURE,
    ),
    ParameterSpec(
        "amplitude.imu_type",
        str,
        "",
        _A + "its type: sensor_msgs/Imu (imu) or feeder_ros/AccelerometerBatch (imu_batch); "
        "x along the track" + _AT_CONFIGURE,
        choices=("imu", "imu_batch"),
    ),
    *(  # the regulator's settings (AmplitudeSettings); floats: minimum excluded
        ParameterSpec(
            f"amplitude.{name}",
            kind,
            unit,
            _A + text + _AT_CONFIGURE,
            low,
            high,
            exclusive_minimum=kind is float,
        )
        for name, kind, unit, text, low, high in (
            ("window_periods", int, "1", "measure over this many drive periods", 2, 100),
            ("gain", float, "1", "share of the correction applied per window", 0.0, 1.0),
            ("max_step_percent", float, "%", "largest amplitude step per window", 0.0, 100.0),
            ("stale_after_s", float, "s", "no window this long: hold, say stale", 0.0, 3600.0),
        )
    ),
)
_AMPLITUDE = AmplitudeSettings()
AMPLITUDE_FIELDS = ("window_periods", "gain", "max_step_percent", "stale_after_s")
AMPLITUDE_DEFAULTS: dict[str, Any] = {
    ENABLED: False,
    SET_POINT: math.nan,
    "amplitude.imu_topic": "imu",
    "amplitude.imu_type": "imu",
    **{f"amplitude.{name}": getattr(_AMPLITUDE, name) for name in AMPLITUDE_FIELDS},
}


def amplitude_settings_from(values: dict[str, Any]) -> AmplitudeSettings:
    return AmplitudeSettings(**{name: values[f"amplitude.{name}"] for name in AMPLITUDE_FIELDS})


PLANT_PARAMETERS = tuple(
    replace(
        spec,
        name=PLANT_PREFIX + spec.name,
        description="speed model plant: " + spec.description + _AT_CONFIGURE,
        read_only=False,
    )
    for spec in PARAMETER_SPECS.values()
    if spec.name not in _PLANT_EXCLUDED
)
PARAMETERS: dict[str, ParameterSpec] = {
    spec.name: spec
    for spec in (
        *LIMIT_PARAMETERS,
        *NODE_PARAMETERS,
        *SPEED_FEEDBACK_PARAMETERS,
        *FEEDING_PARAMETERS,
        *AMPLITUDE_PARAMETERS,
        *TRACKING_PARAMETERS,
        *PLANT_PARAMETERS,
    )
}
#: parameters the node reads when it is configured: changed only while it is unconfigured
AT_CONFIGURE = frozenset(
    name for name, spec in PARAMETERS.items() if spec.description.endswith(_AT_CONFIGURE)
)
_MAP = RegisterMap()
_MODBUS = ModbusSettings()
_TRACKER = TrackerSettings()
TRACKER_FIELDS = (
    "dither_hz",
    "dither_period_s",
    "settle_s",
    "gain_hz2",
    "max_step_hz",
    "amplitude_kp_percent",
    "amplitude_ki_percent",
    "max_amplitude_step_percent",
    "feedback_timeout_s",
)
DEFAULTS: dict[str, Any] = {
    "min_frequency_hz": 5.0,
    "max_frequency_hz": 300.0,
    "max_amplitude_percent": 100.0,
    "max_frequency_rate_hz_per_s": 50.0,
    "max_amplitude_rate_percent_per_s": 50.0,
    "forbidden_bands_hz": "",
    "full_scale_force_n": 100.0,
    "heartbeat_timeout_s": 2.0,
    "backend": "sim",
    "sim_feedback_timeout_s": 1.0,
    "publish_rate_hz": 50.0,
    "diagnostics_period_s": 1.0,
    "speed_model_enabled": True,
    "speed_model_frequency_steps": 30,
    "speed_model_amplitude_steps": 11,
    "speed_model_duration_s": 2.0,
    "speed_model_cache_dir": "",
    "speed_model_file": "",
    "unreachable_speed": "refuse",
    "modbus.host": _MODBUS.host,
    "modbus.port": _MODBUS.port,
    "modbus.device_id": _MODBUS.device_id,
    "modbus.timeout_s": _MODBUS.timeout_s,
    "modbus.poll_period_s": _MODBUS.poll_period_s,
    "modbus.reconnect_min_s": _MODBUS.reconnect_min_s,
    "modbus.reconnect_max_s": _MODBUS.reconnect_max_s,
    "modbus.command_timeout_s": _MODBUS.command_timeout_s,
    **{
        f"modbus.register.{name}": getattr(_MAP, name)
        for name in (
            "command",
            "frequency",
            "amplitude",
            "ramp_time",
            "heartbeat",
            "status",
            "alarm_code",
            "actual_frequency",
            "actual_amplitude",
        )
    },
    "modbus.scale.frequency_counts_per_hz": _MAP.frequency_counts_per_hz,
    "modbus.scale.amplitude_counts_per_percent": _MAP.amplitude_counts_per_percent,
    "modbus.scale.ramp_time_counts_per_s": _MAP.ramp_time_counts_per_s,
    "modbus.status_running_bit": _MAP.status_running_bit,
    "modbus.status_alarm_bit": _MAP.status_alarm_bit,
    "calibration_topic": "calibration",
    "speed_trim.enabled": True,
    "speed_trim.estimate_topic": "estimate",
    "speed_trim.gain": 0.8,
    "speed_trim.max_step": 0.15,
    "speed_trim.max_uncertainty": 0.03,
    "speed_trim.transit_wait_s": 20.0,
    "part_sensor_count": 2,
    "level.mode": "off",
    "level.full_sensor_index": 1,
    "level.low_sensor_index": 0,
    "level.off_delay_s": 1.0,
    "level.on_delay_s": 1.0,
    "level.sensor_timeout_s": 30.0,
    "feed.starvation_timeout_s": 20.0,
    "feed.feedback_period_s": 0.5,
    **AMPLITUDE_DEFAULTS,
    "tracking.enabled": False,
    "tracking.feedback_topic": "estimate",
    "tracking.feedback_type": "vehicle_estimate",
    "tracking.min_confidence": 0.0,
    **{f"tracking.{name}": getattr(_TRACKER, name) for name in TRACKER_FIELDS},
    **{
        PLANT_PREFIX + name: value
        for name, value in FeederParameters().as_dict().items()
        if name not in _PLANT_EXCLUDED
    },
}


def limits_from(values: dict[str, Any]) -> DriveLimits:
    return DriveLimits(
        min_frequency_hz=values["min_frequency_hz"],
        max_frequency_hz=values["max_frequency_hz"],
        max_amplitude_percent=values["max_amplitude_percent"],
        max_frequency_rate_hz_per_s=values["max_frequency_rate_hz_per_s"],
        max_amplitude_rate_percent_per_s=values["max_amplitude_rate_percent_per_s"],
        forbidden_bands_hz=parse_bands(values["forbidden_bands_hz"]),
        full_scale_force_n=values["full_scale_force_n"],
    )


def register_map_from(values: dict[str, Any]) -> RegisterMap:
    registers = {
        key.removeprefix("modbus.register."): value
        for key, value in values.items()
        if key.startswith("modbus.register.")
    }
    scales = {
        key.removeprefix("modbus.scale."): value
        for key, value in values.items()
        if key.startswith("modbus.scale.")
    }
    return RegisterMap(
        **registers,
        **scales,
        status_running_bit=values["modbus.status_running_bit"],
        status_alarm_bit=values["modbus.status_alarm_bit"],
    )


def modbus_settings_from(values: dict[str, Any]) -> ModbusSettings:
    return ModbusSettings(
        host=values["modbus.host"],
        port=values["modbus.port"],
        device_id=values["modbus.device_id"],
        timeout_s=values["modbus.timeout_s"],
        poll_period_s=values["modbus.poll_period_s"],
        reconnect_min_s=values["modbus.reconnect_min_s"],
        reconnect_max_s=values["modbus.reconnect_max_s"],
        command_timeout_s=values["modbus.command_timeout_s"],
    )


def plant_from(values: dict[str, Any]) -> FeederParameters:
    return FeederParameters.from_mapping(
        {
            key.removeprefix(PLANT_PREFIX): value
            for key, value in values.items()
            if key.startswith(PLANT_PREFIX)
        }
    )


def speed_model_source_from(values: dict[str, Any], threads: int = 1) -> SpeedModelSource:
    return SpeedModelSource(
        enabled=bool(values["speed_model_enabled"]),
        file=values["speed_model_file"],
        cache_dir=values["speed_model_cache_dir"],
        frequency_steps=values["speed_model_frequency_steps"],
        amplitude_steps=values["speed_model_amplitude_steps"],
        duration_s=values["speed_model_duration_s"],
        threads=threads,
    )


def tracker_settings_from(values: dict[str, Any]) -> TrackerSettings:
    return TrackerSettings(**{name: values[f"tracking.{name}"] for name in TRACKER_FIELDS})


def level_settings_from(values: dict[str, Any]) -> LevelSettings:
    """The level control's settings, checked against the sensors there are (LevelError)."""
    settings = LevelSettings.from_values(
        values["level.mode"],
        values["level.full_sensor_index"],
        values["level.low_sensor_index"],
        values["level.off_delay_s"],
        values["level.on_delay_s"],
        values["level.sensor_timeout_s"],
    )
    settings.check_sensor_count(values["part_sensor_count"])
    return settings


INTERFACE = NodeInterface(
    executable="drive_interface",
    node_name="drive_interface",
    summary="managed (lifecycle) drive-command interface for the cell controller: limits, soft "
    "ramps, heartbeat watchdog, e-stop, target-speed mode; sim or Modbus TCP backend. Parameters "
    "read at configure are set while it is unconfigured (refused later)",
    publishes=(
        TopicSpec(
            "drive/state",
            "feeder_ros/msg/DriveState",
            "reliable, depth 10",
            "state (idle/ramping/running/fault/e-stop), output, set point, fault reason, "
            "resonance tracking (off/active/hold, tracked peak), level control (state, pause "
            "reason, sensors), feed_parts progress, amplitude regulation (set point, measured "
            "line); at publish_rate_hz once configured",
        ),
        TopicSpec(
            "drive/command",
            "feeder_ros/msg/DriveCommand",
            "reliable, depth 10",
            "sim backend: the output, freshly stamped at publish_rate_hz (enabled=false when off)",
        ),
        TopicSpec(
            "/diagnostics",
            "diagnostic_msgs/msg/DiagnosticArray",
            "reliable, depth 10",
            "OK/WARN/ERROR with state, output, heartbeat age and backend link details, "
            "resonance tracking (WARN while it holds on stale feedback); sim backend: WARN "
            "while nothing subscribes to drive/command",
        ),
    ),
    subscribes=(
        TopicSpec(
            "heartbeat",
            "std_msgs/msg/Header",
            "reliable, depth 10",
            "the cell controller's heartbeat; none for heartbeat_timeout_s: ramp to zero, fault",
        ),
        TopicSpec(
            "parts/state",
            "feeder_ros/msg/PartStateArray",
            "best effort, depth 1",
            "sim backend: the simulator's sign of life; silent for sim_feedback_timeout_s after "
            "it was live: fault (simulator lost)",
        ),
        TopicSpec(
            "parts/sensor_events",
            "feeder_ros/msg/PartSensorEvent",
            "reliable, depth 100",
            "part-present sensor edges: track level control and feed_parts count parts with "
            "them; subscribed at configure",
        ),
        TopicSpec(
            "estimate",
            "feeder_ros/msg/VehicleEstimate",
            "reliable, depth 100",
            "resonance tracking's part-speed feedback: tracking.feedback_topic of "
            "tracking.feedback_type (or e.g. speed/status, feeder_ros/msg/SpeedStatus); "
            "subscribed at configure",
        ),
        TopicSpec(
            "imu",
            "sensor_msgs/msg/Imu",
            "best effort, depth 500",
            "amplitude regulation's carrier accelerometer: amplitude.imu_topic of "
            "amplitude.imu_type (or e.g. imu/batch, feeder_ros/msg/AccelerometerBatch); "
            "subscribed at configure",
        ),
    ),
    services=(
        ServiceSpec("start", "std_srvs/srv/Trigger", "ramp to the set point (needs heartbeat)"),
        ServiceSpec("stop", "std_srvs/srv/Trigger", "ramp to zero"),
        ServiceSpec(
            "set_drive",
            "feeder_ros/srv/SetDrive",
            "set frequency, amplitude, ramp time: ACCEPTED / CLAMPED / REFUSED with reason",
        ),
        ServiceSpec(
            "set_target_speed",
            "feeder_ros/srv/SetTargetSpeed",
            "part speed via the speed model; unreachable: REFUSED with the range (or CLAMPED)",
        ),
        ServiceSpec(
            "set_vibration_amplitude",
            "feeder_ros/srv/SetVibrationAmplitude",
            "amplitude regulation's set point [m/s^2]: ACCEPTED / REFUSED with the reachable range",
        ),
        ServiceSpec("reset_fault", "std_srvs/srv/Trigger", "clear a latched fault or e-stop"),
        ServiceSpec(
            "emergency_stop", "std_srvs/srv/Trigger", "zero output at once; latched until reset"
        ),
        ServiceSpec(
            "feed_parts",
            "feeder_ros/action/FeedParts",
            "action: N parts past a sensor, or until a part is at the pick sensor; feedback "
            "(delivered, speed); result once the output is off; cancel ramps to zero; one goal at "
            "a time (others end REFUSED with the reason)",
        ),
        ServiceSpec(
            "~/change_state",
            "lifecycle_msgs/srv/ChangeState",
            "lifecycle transitions (and ~/get_state, ~/get_available_transitions)",
        ),
    ),
    parameters=PARAMETERS,
)
