"""Speed model: the table inverse (least amplitude), reachability, the physics-backed cache."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.speed_model import (
    TableSpeedModel,
    cached_speed_table,
    compute_speed_table,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import simulate_many


def test_choose_inverts_the_table_where_it_predicts_best() -> None:
    model = TableSpeedModel(
        [20.0, 30.0, 40.0],
        [0.0, 50.0, 100.0],
        [[0.0, 0.010, 0.020], [0.0, 0.030, 0.040], [0.0, -0.01, 0.060]],
    )
    assert model.reachable_range() == (-0.01, 0.06)
    choice = model.choose(0.015)
    assert choice is not None
    # 75 % at 20 Hz (bracket 10..20 mm/s) beats 25 % at 30 Hz (bracket 0..30 mm/s): the
    # interpolation there can be off by at most 10 mm/s instead of 30
    assert choice.frequency_hz == 20.0
    assert choice.amplitude_percent == pytest.approx(75.0)
    assert model.predict(choice.frequency_hz, choice.amplitude_percent) == pytest.approx(0.015)
    fast = model.choose(0.05)
    assert fast is not None
    assert (fast.frequency_hz, fast.amplitude_percent) == (40.0, pytest.approx(50.0 + 50.0 * 6 / 7))
    assert model.choose(0.07) is None
    assert model.nearest(0.07).predicted_speed_mps == pytest.approx(0.06)
    zero = model.choose(0.0)
    assert zero is not None
    assert zero.amplitude_percent == 0.0


def test_choose_avoids_the_steep_slip_threshold() -> None:
    # 10 Hz: nothing moves until 20 %, then the speed shoots up (the slip threshold);
    # 20 Hz: the speed grows evenly with amplitude. The even row is the robust choice.
    model = TableSpeedModel(
        [10.0, 20.0],
        [0.0, 10.0, 20.0, 30.0, 40.0],
        [[0.0, 0.0, 0.0, 0.030, 0.032], [0.0, 0.004, 0.008, 0.012, 0.016]],
    )
    choice = model.choose(0.010)
    assert choice is not None
    assert (choice.frequency_hz, choice.amplitude_percent) == (20.0, pytest.approx(25.0))


def test_choose_prefers_a_setting_the_amplitude_steers_over_a_plateau() -> None:
    """22 Hz: a plateau (8.1 -> 8.7 mm/s from 25 to 30 %, d ln v/d ln A about 0.4), the bracket
    whose ends differ least; 30 Hz: 6 -> 10 mm/s over 50 -> 80 % (1.08 at 8.4 mm/s). The plateau's
    speed is set by friction, not by the amplitude: 30 Hz is chosen; with no steerable bracket
    the plateau still is."""
    amplitudes = [0.0, 25.0, 30.0, 50.0, 80.0]
    plateau = [0.0, 0.0081, 0.0087, 0.0095, 0.0140]
    even = [0.0, 0.0020, 0.0030, 0.0060, 0.0100]
    model = TableSpeedModel([22.0, 30.0], amplitudes, [plateau, even])
    choice = model.choose(0.0084)
    assert choice is not None
    assert choice.frequency_hz == 30.0
    assert model.amplitude_sensitivity(30.0, choice.amplitude_percent) == pytest.approx(
        (0.004 / 30.0) * choice.amplitude_percent / 0.0084
    )
    assert 0.5 <= model.amplitude_sensitivity(30.0, choice.amplitude_percent) <= 2.0
    assert model.amplitude_sensitivity(22.0, 27.5) < 0.5
    alone = TableSpeedModel([22.0], amplitudes, [plateau])
    only = alone.choose(0.0084)
    assert only is not None
    assert only.amplitude_percent == pytest.approx(27.5)


def test_amplitude_sensitivity_is_the_tables_log_slope() -> None:
    """A piecewise linear row: the interval's slope times A/v, the two intervals' on an inner
    grid point; NaN where v <= 0 or the speed falls."""
    amplitudes = np.array([10.0, 20.0, 40.0, 80.0])
    model = TableSpeedModel([30.0], amplitudes, [[-0.001, 0.0, 0.002, 0.004]])
    # 40..80 %: slope 0.002/40 per %, at 60 % v = 0.003: 0.05e-3 * 60 / 0.003 = 1
    assert model.amplitude_sensitivity(30.0, 60.0) == pytest.approx(1.0)
    assert model.amplitude_sensitivity(31.0, 30.0) == pytest.approx(1e-4 * 30.0 / 0.001)
    assert np.isnan(model.amplitude_sensitivity(30.0, 15.0))  # v = -0.0005 there
    assert np.isnan(model.amplitude_sensitivity(30.0, 20.0))  # v = 0
    # on the grid point 40 %: the slope from 20 to 80 %, 0.004/60 per %, times 40/0.002
    assert model.amplitude_sensitivity(30.0, 40.0) == pytest.approx(0.004 / 60.0 * 40.0 / 0.002)
    falling = TableSpeedModel([30.0], [0.0, 50.0, 100.0], [[0.0, 0.006, 0.004]])
    assert np.isnan(falling.amplitude_sensitivity(30.0, 75.0))


def test_choose_at_one_frequency_searches_that_row_only() -> None:
    model = TableSpeedModel(
        [20.0, 30.0], [0.0, 50.0, 100.0], [[0.0, 0.004, 0.01], [0.0, 0.002, 0.005]]
    )
    anywhere = model.choose(0.005)
    assert anywhere is not None
    assert anywhere.frequency_hz == 30.0  # the flatter bracket (2..5 mm/s)
    at_20 = model.choose(0.005, 21.0)  # the nearest row, 20 Hz
    assert at_20 is not None
    assert at_20.frequency_hz == 20.0
    assert at_20.amplitude_percent == pytest.approx(50.0 + 50.0 / 6.0)
    assert model.choose(0.008, 30.0) is None  # 30 Hz tops out at 5 mm/s


def test_table_shape_and_grid_are_validated() -> None:
    with pytest.raises(ValueError, match="shape"):
        TableSpeedModel([20.0], [0.0, 100.0], [[0.0, 0.1, 0.2]])
    with pytest.raises(ValueError, match="increasing"):
        TableSpeedModel([20.0], [50.0, 0.0], [[0.0, 0.1]])


def test_physics_table_matches_simulate_many_and_respects_forbidden_bands() -> None:
    plant = FeederParameters()
    limits = DriveLimits(
        min_frequency_hz=10.0, max_frequency_hz=60.0, forbidden_bands_hz=((26.0, 34.0),)
    )
    model = compute_speed_table(
        plant, limits, frequency_steps=11, amplitude_steps=3, duration_s=1.0
    )
    assert not np.any((model.frequencies_hz > 26.0) & (model.frequencies_hz < 34.0))
    assert model.frequencies_hz.min() == 10.0
    assert model.frequencies_hz.max() == 60.0
    np.testing.assert_array_equal(model.amplitudes_percent, [0.0, 50.0, 100.0])
    np.testing.assert_array_equal(model.speeds_mps[:, 0], 0.0)  # no drive, no motion
    # one entry recomputed directly: 50 % of 100 N full scale = 50 N
    row = int(np.argmin(np.abs(model.frequencies_hz - 20.0)))
    point = plant.with_changes(
        drive_frequency_hz=float(model.frequencies_hz[row]), drive_amplitude_n=50.0
    )
    direct = simulate_many([point], 1.0).mean_part_speed_mps[0]
    assert model.speeds_mps[row, 1] == pytest.approx(direct, rel=1e-12, abs=1e-15)


def test_cache_is_keyed_by_the_inputs(tmp_path: Path) -> None:
    plant = FeederParameters()
    limits = DriveLimits(min_frequency_hz=10.0, max_frequency_hz=60.0)
    first, path, loaded = cached_speed_table(plant, limits, tmp_path, 5, 3, 0.5)
    assert not loaded
    assert path.is_file()
    again, path_again, loaded_again = cached_speed_table(plant, limits, tmp_path, 5, 3, 0.5)
    assert loaded_again
    assert path_again == path
    np.testing.assert_array_equal(again.speeds_mps, first.speeds_mps)
    heavier = plant.with_changes(part_mass_kg=0.1)
    _, other_path, other_loaded = cached_speed_table(heavier, limits, tmp_path, 5, 3, 0.5)
    assert other_path != path
    assert not other_loaded
    path.write_bytes(b"damaged")
    _, _, loaded_damaged = cached_speed_table(plant, limits, tmp_path, 5, 3, 0.5)
    assert not loaded_damaged  # recomputed, not crashed


def test_a_table_that_cannot_be_cached_is_still_returned_or_the_error_raised(
    tmp_path: Path,
) -> None:
    plant = FeederParameters()
    limits = DriveLimits(min_frequency_hz=10.0, max_frequency_hz=60.0)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    cache = blocker / "sub"  # under a file: the directory cannot be made
    with pytest.raises(OSError, match="a_file"):
        cached_speed_table(plant, limits, cache, 5, 3, 0.5)
    errors: list[OSError] = []
    model, path, loaded = cached_speed_table(
        plant, limits, cache, 5, 3, 0.5, on_store_error=errors.append
    )
    assert not loaded
    assert not path.exists()
    assert len(errors) == 1
    assert isinstance(errors[0], NotADirectoryError | FileExistsError)
    reference, _, _ = cached_speed_table(plant, limits, tmp_path / "ok", 5, 3, 0.5)
    np.testing.assert_array_equal(model.speeds_mps, reference.speeds_mps)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "ok"]
