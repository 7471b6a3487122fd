from __future__ import annotations

import math

from feeder_ros.csv_cells import csv_cell


def test_floats_read_back_exactly_and_flags_as_digits() -> None:
    for value in (0.1, 1.0 / 3.0, -2.5e-300, 1e22):
        assert float(csv_cell(value)) == value
    assert math.isnan(float(csv_cell(math.nan)))
    assert float(csv_cell(-math.inf)) == -math.inf
    assert csv_cell(True) == "1"
    assert csv_cell(False) == "0"
    assert csv_cell(7) == "7"
    assert csv_cell("hold") == "hold"
