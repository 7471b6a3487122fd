"""Sensor transit speeds count only transits whose whole passage (entry at the first sensor to
arrival at the second) lies within one steady drive segment: one that entered under the previous
setting or during its ramp would pull a short segment's speed toward the old one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from rclpy.serialization import serialize_message

from feeder_ros.bag import BagWriter
from feeder_ros.bag.analysis import analyze_bag
from feeder_ros.msg import CarrierState, PartSensorEvent

T0 = 1_770_000_000_000_000_000
MS = 1_000_000
S = 1_000_000_000
GAP_M = 0.010  # the sensors are 10 mm apart
SLOW, FAST = 0.005, 0.008  # part speeds under the two settings [m/s]


def stamp(message: Any, t_ns: int) -> Any:
    message.header.stamp.sec = t_ns // S
    message.header.stamp.nanosec = t_ns % S
    return message


def drive(k_ms: int) -> float:
    """Drive frequency: 30 Hz to 3.0 s, a 0.2 s ramp to 40 Hz, 40 Hz to 5.0 s (a short segment)."""
    if k_ms < 3000:
        return 30.0
    if k_ms < 3200:
        return 30.0 + 10.0 * (k_ms - 3000) / 200
    return 40.0


def position_mm(enter_ms: int, t_ms: float) -> float:
    """Distance travelled since ``enter_ms`` by a part at SLOW until 3.0 s, accelerating linearly
    to FAST over the ramp, FAST after it [mm]."""

    def x(t: float) -> float:  # from t = 0
        slow, fast = SLOW * 1e3, FAST * 1e3  # mm/s
        if t <= 3.0:
            return slow * t
        if t <= 3.2:
            tau = t - 3.0
            return slow * 3.0 + slow * tau + 0.5 * (fast - slow) / 0.2 * tau**2
        return slow * 3.0 + 0.2 * (slow + fast) / 2 + fast * (t - 3.2)

    return x(t_ms / 1000) - x(enter_ms / 1000)


def arrival_ms(enter_ms: int) -> int:
    """When a part that entered at ``enter_ms`` has gone GAP_M (to the ms)."""
    t = enter_ms
    while position_mm(enter_ms, t) < GAP_M * 1e3 - 1e-9:
        t += 1
    return t


# (part, entry ms): part 1 within the 30 Hz segment; part 2 enters at 30 Hz and arrives at 40 Hz
# (across the ramp); parts 3 and 4 within the short 40 Hz segment
ENTRIES = [(1, 500), (2, 2400), (3, 3300), (4, 3500)]


def write_bag(path: Path) -> dict[int, tuple[int, int]]:
    transits = {part: (enter, arrival_ms(enter)) for part, enter in ENTRIES}
    with BagWriter(path, chunk_size=16 << 10) as w:
        w.add_topic("/f/carrier/state", "feeder_ros/msg/CarrierState")
        w.add_topic("/f/parts/sensor_events", "feeder_ros/msg/PartSensorEvent")
        edges = sorted(
            (t, sensor, part) for part, times in transits.items() for sensor, t in enumerate(times)
        )
        for k in range(5000):
            t_ns = T0 + k * MS
            state = CarrierState(drive_frequency_hz=drive(k), drive_amplitude_n=20.0)
            w.write("/f/carrier/state", bytes(serialize_message(stamp(state, t_ns))), t_ns)
            for when, sensor, part in edges:
                if when == k:
                    event = PartSensorEvent(
                        sensor_index=sensor,
                        sensor_position_m=0.05 + sensor * GAP_M,
                        part_id=part,
                        present=True,
                    )
                    w.write(
                        "/f/parts/sensor_events", bytes(serialize_message(stamp(event, t_ns))), t_ns
                    )
    return transits


def test_transits_across_a_drive_change_are_left_out(tmp_path: Path) -> None:
    transits = write_bag(tmp_path / "bag")
    assert transits[1] == (500, 2500)  # 10 mm at 5 mm/s
    assert transits[3] == (3300, 4550)  # 10 mm at 8 mm/s
    enter, arrive = transits[2]
    straddling = GAP_M / ((arrive - enter) * 1e-3)
    assert 0.0055 < straddling < 0.0075  # neither speed: 5 mm/s before the ramp, 8 after it

    result = analyze_bag(tmp_path / "bag")
    slow, fast = result.segments  # the ramp's 1 ms steps are transient segments, left out
    assert (slow.frequency_hz, fast.frequency_hz) == (30.0, 40.0)
    assert fast.start_s == pytest.approx(3.2)
    assert fast.duration_s < 2.0  # a short segment: one straddling transit in three weighs
    assert slow.speed_sensors_mps == pytest.approx(SLOW, rel=1e-9)
    # counting part 2 would give (straddling + 2 * FAST) / 3, 6 % low
    assert fast.speed_sensors_mps == pytest.approx(FAST, rel=1e-9)
    assert (slow.transits, slow.transits_left_out) == (1, 0)
    assert (fast.transits, fast.transits_left_out) == (2, 1)
    assert fast.as_dict()["transits_left_out"] == 1
