"""The live sweep's meters without ROS (:mod:`feeder_ros.identification.live_meters`)."""

from __future__ import annotations

import math

import pytest

from feeder_ros.identification.live_meters import StatusMeter, TransitMeter, TruthMeter


def test_transit_meter_pairs_edges_and_keeps_to_the_window() -> None:
    meter = TransitMeter()
    meter.add(0.5, 0, 0.10, 7, True)  # part 7 enters before the window: not counted
    meter.add(1.2, 0, 0.10, 8, True)
    meter.add(1.3, 0, 0.10, 8, False)  # falling edges are ignored
    meter.add(1.4, 1, 0.11, 7, True)
    meter.add(1.7, 1, 0.11, 8, True)  # part 8: 1 cm in 0.5 s
    meter.add(2.0, 0, 0.10, None, True)  # sensors without part ids: first in, first out
    meter.add(2.1, 0, 0.10, None, True)
    meter.add(2.25, 1, 0.11, None, True)  # the part that entered at 2.0: 1 cm in 0.25 s
    meter.add(3.5, 1, 0.11, None, True)  # the one of 2.1, after the window's end
    window = meter.measure(1.0, 3.0)
    assert window.count == 2
    assert window.speed_mps == pytest.approx((0.02 + 0.04) / 2)
    assert window.duration_s == pytest.approx((0.5 + 0.25) / 2)
    assert meter.distance_m == pytest.approx(0.01)
    assert meter.latest_s == 3.5
    first = meter.first_transit(1.0)
    assert first is not None
    assert first.speed_mps == pytest.approx(0.02)
    assert meter.first_transit(2.2) is None
    assert not meter.measure(5.0, 9.0).ok


def test_status_and_truth_meters() -> None:
    status = StatusMeter()
    for k in range(11):
        status.add(k * 0.5, 0.01 if k < 6 else 0.02)
    status.add(5.5, math.nan)  # unknown speed: ignored
    assert status.measure(0.0, 2.0).speed_mps == pytest.approx(0.01)
    assert status.measure(0.0, 2.0).count == 5
    covered = status.covered(0.0, 4.0)  # each sample held until the next: 3 s of 10 mm/s, 1 s of 20
    assert covered.covered_m == pytest.approx(0.05)
    assert covered.speed_mps == pytest.approx(0.05 / 4.0)
    truth = TruthMeter()
    truth.add(0.9, {1: 0.0})
    truth.add(1.0, {1: 0.010, 2: 0.0})
    truth.add(2.0, {1: 0.030, 2: 0.01, 3: 0.0})  # part 3 new: not in the first snapshot
    truth.add(3.0, {2: 0.03})  # part 1 left the track
    m = truth.measure(1.0, 2.0)
    assert m.count == 2
    assert m.speed_mps == pytest.approx(0.015)
    assert truth.measure(1.0, 3.0).speed_mps == pytest.approx(0.015)  # part 2 only
