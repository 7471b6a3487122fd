"""The bag source: bags of a sweep written from code (real ROS messages serialized by rclpy), read
back as sweep points; every value is known from what was written."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from rclpy.serialization import serialize_message

from feeder_ros.bag import BagWriter
from feeder_ros.bag.analysis import AnalysisError
from feeder_ros.identification.bag_sweep import sweep_from_bags
from feeder_ros.identification.sweep import SweepDataError
from feeder_ros.msg import CarrierState, PartSensorEvent, PartState, PartStateArray

T0 = 1_760_000_000_000_000_000
MS = 1_000_000
S = 1_000_000_000
NS = "/bag_sweep/feeder"

# (duration s, frequency Hz, amplitude N, true mean part speed m/s) of the recorded sweep: steady
# points, a ramp of 50 ms steps between the first two (transient), a point too short to count,
# an amplitude change, and the drive off at the end
SWEEP = [
    (2.0, 20.0, 40.0, 0.016),
    *[(0.05, 20.0 + 0.25 * k, 40.0, 0.016) for k in (1, 2, 3)],
    (2.0, 21.0, 40.0, 0.012),
    (0.8, 22.0, 40.0, 0.009),
    (2.0, 23.0, 30.0, 0.004),
    (1.0, 23.0, 0.0, 0.0),
]
STEADY = [(2.0, 20.0, 40.0, 0.016), (2.0, 21.0, 40.0, 0.012), (2.0, 23.0, 30.0, 0.004)]


def stamp(message: Any, t_ns: int) -> Any:
    message.header.stamp.sec = t_ns // S
    message.header.stamp.nanosec = t_ns % S
    return message


def plan_at(t_s: float) -> tuple[float, float, float]:
    start = 0.0
    for duration, frequency, amplitude, speed in SWEEP:
        if t_s < start + duration - 1e-9:
            return frequency, amplitude, speed
        start += duration
    return SWEEP[-1][1:]


def write_sweep_bag(path: Path, truth: bool = True, sensors: bool = False) -> None:
    """The SWEEP above: carrier state at 100 Hz; with ``truth`` two parts' states at 50 Hz
    (moving at speed -+ 1 mm/s: their mean is the speed); with ``sensors`` one part per steady
    point timed over 5 mm at exactly the point's speed."""
    total_ms = round(sum(d for d, *_ in SWEEP) * 1000)
    with BagWriter(path) as writer:
        writer.add_topic(f"{NS}/carrier/state", "feeder_ros/msg/CarrierState")
        writer.add_topic(f"{NS}/parts/state", "feeder_ros/msg/PartStateArray")
        writer.add_topic(f"{NS}/parts/sensor_events", "feeder_ros/msg/PartSensorEvent")

        def put(topic: str, message: Any, t_ns: int) -> None:
            writer.write(f"{NS}/{topic}", bytes(serialize_message(stamp(message, t_ns))), t_ns)

        events: list[tuple[int, PartSensorEvent]] = []
        if sensors:
            start = 0.0
            for part, (duration, _, amplitude, speed) in enumerate(SWEEP, start=1):
                if duration >= 2.0 and amplitude > 0.0:  # one transit inside each steady point
                    for index, position, at in ((0, 0.1, 0.3), (1, 0.105, 0.3 + 0.005 / speed)):
                        if at < duration:
                            event = PartSensorEvent(
                                sensor_index=index,
                                sensor_position_m=position,
                                part_id=part,
                                present=True,
                            )
                            events.append((T0 + round((start + at) * S), event))
                start += duration
        places = [0.0, 0.0]  # the two parts' positions, moved at their speeds
        for k in range(0, total_ms, 10):
            t_ns = T0 + k * MS
            frequency, amplitude, speed = plan_at(k / 1000)
            state = CarrierState(drive_frequency_hz=frequency, drive_amplitude_n=amplitude)
            put("carrier/state", state, t_ns)
            if truth and k % 20 == 0:
                velocities = (speed - 0.001, speed + 0.001)
                if k:  # over the 20 ms up to this sample
                    places = [x + v * 0.02 for x, v in zip(places, velocities, strict=True)]
                parts = PartStateArray(
                    parts=[
                        PartState(
                            part_id=i + 1,
                            position_m=places[i],
                            velocity_mps=velocities[i],
                            on_track=True,
                        )
                        for i in (0, 1)
                    ]
                )
                put("parts/state", parts, t_ns)
            while events and events[0][0] <= t_ns:
                t_event, event = events.pop(0)
                put("parts/sensor_events", event, t_event)


def test_steady_segments_become_points_with_ground_truth(tmp_path: Path) -> None:
    bag = tmp_path / "sweep_bag"
    write_sweep_bag(bag)
    swept = sweep_from_bags([bag], full_scale_force_n=100.0, part_masses_kg=[0.031],
                            min_duration_s=1.5)  # fmt: skip
    result = swept.result
    assert result.source == "bag sweep_bag"
    assert result.full_scale_force_n == 100.0
    good = [p for p in result.points if p.ok]
    assert [(p.frequency_hz, p.amplitude_n) for p in good] == [(f, a) for _, f, a, _ in STEADY]
    for point, (duration, _, amplitude, speed) in zip(good, STEADY, strict=True):
        assert point.speed_mps == pytest.approx(speed, abs=1e-12)
        assert point.amplitude_percent == pytest.approx(amplitude)  # 100 N full scale
        assert point.duration_s == pytest.approx(duration, abs=0.011)  # 10 ms grid
        assert point.part_mass_kg == 0.031
    # the 0.8 s point is kept, not usable, with the reason; the ramp and the "off" are no points
    short = [p for p in result.points if not p.ok]
    assert len(short) == 1
    assert short[0].frequency_hz == 22.0
    assert "shorter than 1.5 s" in short[0].reason
    assert len(result) == 4
    assert swept.speed_sources() == {"ground truth": 4}
    assert swept.analyses[0].transient_segments == 3


def test_sensor_transits_give_the_speed_without_ground_truth(tmp_path: Path) -> None:
    bag = tmp_path / "sensors_only"
    write_sweep_bag(bag, truth=False, sensors=True)
    swept = sweep_from_bags([bag], full_scale_force_n=80.0, part_masses_kg=[0.06])
    good = [p for p in swept.result.points if p.ok and p.duration_s > 1.0]
    assert len(good) == 3
    for point, (_, _, amplitude, speed) in zip(good, STEADY, strict=True):
        assert point.speed_mps == pytest.approx(speed, rel=1e-6)  # 5 mm over its transit time
        assert point.amplitude_percent == pytest.approx(amplitude / 80.0 * 100.0)
    # the 0.8 s point has no transit: kept, not usable, with the reason
    silent = [p for p in swept.result.points if p.frequency_hz == 22.0]
    assert not silent[0].ok
    assert "no part speed" in silent[0].reason
    assert swept.speed_sources() == {"sensor transits": 3, "none": 1}


def test_masses_per_bag_and_refusals(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    write_sweep_bag(a)
    write_sweep_bag(b)
    swept = sweep_from_bags([a, b], full_scale_force_n=100.0, part_masses_kg=[0.031, 0.06])
    masses = [p.part_mass_kg for p in swept.result.points]
    assert masses == [0.031] * 4 + [0.06] * 4
    assert {g.part_mass_kg for g in swept.result.groups()} == {0.031, 0.06}
    with pytest.raises(SweepDataError, match="3 part masses for 2 bags"):
        sweep_from_bags([a, b], full_scale_force_n=100.0, part_masses_kg=[0.03, 0.04, 0.05])
    with pytest.raises(SweepDataError, match="no bags"):
        sweep_from_bags([], full_scale_force_n=100.0, part_masses_kg=[0.03])
    with pytest.raises(SweepDataError, match="full_scale_force_n"):
        sweep_from_bags([a], full_scale_force_n=0.0, part_masses_kg=[0.03])
    empty = tmp_path / "empty"
    with BagWriter(empty) as writer:
        writer.add_topic("/chatter", "std_msgs/msg/String")
    with pytest.raises(AnalysisError, match=r"no feeder topics|empty bag"):
        sweep_from_bags([empty], full_scale_force_n=100.0, part_masses_kg=[0.03])


def test_a_bag_without_driven_segments_is_refused(tmp_path: Path) -> None:
    bag = tmp_path / "off"
    with BagWriter(bag) as writer:
        writer.add_topic(f"{NS}/carrier/state", "feeder_ros/msg/CarrierState")
        for k in range(200):
            message = stamp(CarrierState(drive_frequency_hz=20.0), T0 + k * 10 * MS)
            writer.write(f"{NS}/carrier/state", bytes(serialize_message(message)), T0 + k * 10 * MS)
    with pytest.raises(SweepDataError, match="no driven segment"):
        sweep_from_bags([bag], full_scale_force_n=100.0, part_masses_kg=[0.03])


def test_a_bag_of_two_feeders_is_refused_unless_a_namespace_picks_one(tmp_path: Path) -> None:
    from bag.test_feeders import FEEDERS, write_two_feeders

    from feeder_ros.bag.errors import BagError

    path = tmp_path / "two"
    write_two_feeders(path)
    with pytest.raises(BagError, match=r"/feeder_a.*/feeder_b"):
        sweep_from_bags([path], full_scale_force_n=100.0, part_masses_kg=[0.01])
    swept = sweep_from_bags(
        [path], full_scale_force_n=100.0, part_masses_kg=[0.01], namespace="/feeder_b"
    )
    frequencies = sorted({p.frequency_hz for p in swept.result.points})
    assert frequencies == [40.0]
    speeds = [p.speed_mps for p in swept.result.points]
    assert speeds == pytest.approx([FEEDERS["/feeder_b"]["speed"]] * len(speeds), rel=0.02)
