"""Parameters of the platform simulator node besides the model's (ROS-free, shared with the CLI).

The model parameters are :data:`feeder_ros.physics.parameters.PARAMETER_SPECS`; these are the
node's own: sample rates, pacing, the sensors it simulates, the parts it puts on the track and the
end of the track (open, or a stopper where parts queue until picked). Also the node's declared
interface (:data:`INTERFACE`: topics, services, every parameter) and the check of a parameter set
as a whole (:func:`check_combination`), so docs and tests read them without starting ROS.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from feeder_ros.node_interfaces import NodeInterface, ServiceSpec, TopicSpec
from feeder_ros.physics.parameters import PARAMETER_SPECS, FeederParameters, ParameterSpec

#: model parameters that mean more to the node: the track length is also where a stopper stands
NODE_MODEL_SPECS: dict[str, ParameterSpec] = {
    "track_length_m": dataclasses.replace(
        PARAMETER_SPECS["track_length_m"],
        description="track length: a part past it leaves the feeder (track_end open), or the "
        "stopper where parts queue (track_end stopper)",
    )
}
NODE_PARAMETERS: dict[str, ParameterSpec] = {
    spec.name: spec
    for spec in (
        ParameterSpec(
            "imu_rate_hz", float, "Hz", "accelerometer sample rate", 1.0, 20000.0, read_only=True
        ),
        ParameterSpec(
            "state_rate_hz", float, "Hz", "carrier state sample rate", 1.0, 20000.0, read_only=True
        ),
        ParameterSpec(
            "parts_rate_hz", float, "Hz", "part states publish rate", 0.1, 1000.0, read_only=True
        ),
        ParameterSpec(
            "publish_batches",
            bool,
            "",
            "publish IMU and carrier state as batches (imu/batch, carrier/state_batch), one per "
            "step, instead of one message per sample: for high rates and faster than real time",
            read_only=True,
        ),
        ParameterSpec(
            "tick_period_s",
            float,
            "s",
            "wall time between simulation steps",
            0.001,
            1.0,
            read_only=True,
        ),
        ParameterSpec(
            "real_time_factor",
            float,
            "1",
            "simulated seconds per wall second; 0: as fast as possible (needs use_sim_time; "
            "too fast for a live drive interface, whose commands arrive stale)",
            minimum=0.0,
            maximum=1000.0,
        ),
        ParameterSpec(
            "max_lag_s",
            float,
            "s",
            "trailing the paced schedule by this much means the simulator cannot keep up: "
            "diagnostics ERROR (WARN from 0.1 s); its sensor data then run late",
            0.1,
            3600.0,
        ),
        ParameterSpec(
            "max_step_s",
            float,
            "s",
            "largest simulated step (a tick takes as many as the pace needs)",
            0.001,
            10.0,
        ),
        ParameterSpec(
            "command_timeout_s",
            float,
            "s",
            "a drive command older than this is a stop; 0 disables",
            minimum=0.0,
        ),
        ParameterSpec("initial_parts", int, "1", "parts on the track at start", 0, 10000),
        ParameterSpec("part_start_m", float, "m", "track position of new parts", minimum=0.0),
        ParameterSpec(
            "part_spacing_m", float, "m", "distance between parts put down together", 0.0
        ),
        ParameterSpec(
            "feed_interval_s",
            float,
            "s",
            "put a new part at part_start_m this often (a bowl feeding the track; let go at "
            "rest, as ~/spawn_parts does), skipped while a part on the track lies within "
            "part_length_m of it (the bowl's exit is blocked); 0: off",
            minimum=0.0,
        ),
        ParameterSpec(
            "part_length_m",
            float,
            "m",
            "part length seen by the sensors and, with a stopper (track_end), its slot in the "
            "queue; read at start and on reset",
            0.0,
            1.0,
        ),
        ParameterSpec(
            "track_end",
            str,
            "",
            "open: parts leave at track_length_m (parts/exit); stopper: they queue there, each "
            "part_length_m long and sitting still, until picked (pick_interval_s, ~/pick_part); "
            "feeds onto a full track are skipped",
            choices=("open", "stopper"),
            read_only=True,
        ),
        ParameterSpec(
            "pick_interval_s",
            float,
            "s",
            "track_end stopper: a robot picks the front part this often (published on "
            "parts/exit); 0: only on request (~/pick_part)",
            minimum=0.0,
        ),
        ParameterSpec(
            "sensor_positions_m",
            str,
            "m",
            "comma-separated track positions of part-present sensors",
            read_only=True,
        ),
        ParameterSpec(
            "imu_noise_density_mps2_per_sqrt_hz",
            float,
            "m/s^2/sqrt(Hz)",
            "accelerometer white-noise density",
            minimum=0.0,
        ),
        ParameterSpec("imu_bias_mps2", float, "m/s^2", "accelerometer bias along the track"),
        ParameterSpec(
            "imu_gain",
            float,
            "1",
            "accelerometer scale factor (reads gain * true acceleration)",
            0.5,
            2.0,
        ),
        ParameterSpec(
            "imu_misalignment_deg",
            float,
            "deg",
            "accelerometer mounting tilt about the cross-track axis (x leans towards z)",
            -45.0,
            45.0,
        ),
        ParameterSpec(
            "imu_saturation_mps2",
            float,
            "m/s^2",
            "accelerometer full scale",
            minimum=0.0,
            exclusive_minimum=True,
        ),
        ParameterSpec("imu_seed", int, "1", "noise seed (same seed, same noise)", minimum=0),
        ParameterSpec("imu_frame_id", str, "", "frame of the accelerometer"),
    )
}
NODE_DEFAULTS: dict[str, Any] = {
    "imu_rate_hz": 1000.0,
    "state_rate_hz": 1000.0,
    "parts_rate_hz": 50.0,
    "publish_batches": False,
    "tick_period_s": 0.01,
    "real_time_factor": 1.0,
    "max_lag_s": 1.0,
    "max_step_s": 0.05,
    "command_timeout_s": 1.0,
    "initial_parts": 1,
    "part_start_m": 0.0,
    "part_spacing_m": 0.02,
    "feed_interval_s": 0.0,
    "part_length_m": 0.01,
    "track_end": "open",
    "pick_interval_s": 0.0,
    "sensor_positions_m": "0.1, 0.185",
    "imu_noise_density_mps2_per_sqrt_hz": 0.0015,
    "imu_bias_mps2": 0.0,
    "imu_gain": 1.0,
    "imu_misalignment_deg": 0.0,
    "imu_saturation_mps2": 156.9,
    "imu_seed": 1,
    "imu_frame_id": "carrier_imu",
}


def parse_positions(text: str) -> list[float]:
    """Sensor positions from "0.1, 0.185"; refuses NaN, negatives and garbage with the value."""
    positions: list[float] = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        try:
            value = float(item)
        except ValueError:
            raise ValueError(f"sensor_positions_m: {item!r} is not a number") from None
        if not math.isfinite(value) or value < 0.0:
            raise ValueError(f"sensor_positions_m: {item!r} must be a finite position >= 0")
        positions.append(value)
    return sorted(positions)


#: the model's drive parameters mean something else to the node: its drive comes from
#: drive/command (the drive interface), never from a parameter. They stay declared, read-only,
#: so the simulator's YAML (shared with ``feeder sim``, whose drive they are) loads without a
#: warning, and a `ros2 param set` is refused with the reason instead of doing nothing.
NODE_DRIVE_SPECS = {
    "drive_frequency_hz": dataclasses.replace(
        PARAMETER_SPECS["drive_frequency_hz"],
        read_only=True,
        description="drive frequency reported before the first drive/command; the node is "
        "driven only by drive/command (`feeder sim`: the drive frequency f_d)",
    ),
    "drive_amplitude_n": dataclasses.replace(
        PARAMETER_SPECS["drive_amplitude_n"],
        read_only=True,
        description="not used by the node, which starts at rest and is driven only by "
        "drive/command (`feeder sim`: the drive amplitude A)",
    ),
}
PARAMETERS = {**PARAMETER_SPECS, **NODE_DRIVE_SPECS, **NODE_MODEL_SPECS, **NODE_PARAMETERS}

INTERFACE = NodeInterface(
    executable="platform_simulator",
    node_name="platform_simulator",
    summary="simulates the carrier and its parts (exact stick-slip physics) under drive commands",
    subscribes=(
        TopicSpec(
            "drive/command",
            "feeder_ros/msg/DriveCommand",
            "reliable, depth 10",
            "drive force; applied at its stamp, a stale one is a stop; one stamped over 1 s "
            "ahead, or outside 0 < f <= 1e5 Hz, 0 <= A <= 1e6 N, a finite ramp >= 0, is "
            "ignored (warning)",
        ),
    ),
    publishes=(
        TopicSpec(
            "imu",
            "sensor_msgs/msg/Imu",
            "best effort, depth 100",
            "carrier accelerometer, x along track",
        ),
        TopicSpec(
            "imu/batch",
            "feeder_ros/msg/AccelerometerBatch",
            "best effort, depth 100",
            "the same samples in batches (publish_batches)",
        ),
        TopicSpec(
            "carrier/state",
            "feeder_ros/msg/CarrierState",
            "reliable, depth 1000",
            "carrier displacement, velocity, acceleration, stiffness branch, drive (ground truth)",
        ),
        TopicSpec(
            "carrier/state_batch",
            "feeder_ros/msg/CarrierStateBatch",
            "reliable, depth 1000",
            "the same samples in batches (publish_batches)",
        ),
        TopicSpec(
            "parts/state",
            "feeder_ros/msg/PartStateArray",
            "reliable, depth 1000",
            "the position, velocity and phase of each part on the track (ground truth; parts "
            "queued at a stopper at their slots, sticking); a part that left is listed once "
            "more, with on_track false",
        ),
        TopicSpec(
            "parts/sensor_events",
            "feeder_ros/msg/PartSensorEvent",
            "reliable, depth 1000",
            "part-present sensor edges at sensor_positions_m",
        ),
        TopicSpec(
            "parts/exit",
            "feeder_ros/msg/PartExit",
            "reliable, depth 1000",
            "a part left the feeder (feed count): past the end of the track, or picked at the "
            "stopper (track_end)",
        ),
        TopicSpec("/clock", "rosgraph_msgs/msg/Clock", "reliable", "simulated time (use_sim_time)"),
        TopicSpec(
            "/diagnostics",
            "diagnostic_msgs/msg/DiagnosticArray",
            "reliable, depth 10",
            "simulation health at 1 Hz: achieved real-time factor, lag, samples, parts; with a "
            "stopper the queue, parts picked, feeds skipped on a full track",
        ),
    ),
    services=(
        ServiceSpec("~/reset", "std_srvs/srv/Trigger", "back to t = 0 with the initial parts"),
        ServiceSpec("~/spawn_parts", "feeder_ros/srv/SpawnParts", "put parts on the track"),
        ServiceSpec(
            "~/pick_part",
            "std_srvs/srv/Trigger",
            "pick the front part at the stopper now (parts/exit); refused with the reason when "
            "the queue is empty or track_end is open",
        ),
    ),
    parameters=PARAMETERS,
)


def check_combination(values: dict[str, Any]) -> None:
    FeederParameters.from_mapping({k: values[k] for k in PARAMETER_SPECS})
    parse_positions(values["sensor_positions_m"])
    if values["real_time_factor"] == 0.0 and not values.get("use_sim_time", False):
        raise ValueError("real_time_factor=0 (unpaced) needs use_sim_time=true")
    if values["track_end"] == "stopper" and values["part_length_m"] <= 0.0:
        raise ValueError("track_end=stopper needs part_length_m > 0 (the queue's slot)")
