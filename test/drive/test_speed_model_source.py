"""Where the drive's speed model comes from (feeder_ros.drive.speed_model_source): none when
disabled, the identified model from a file, else the plant's physics table (cached), each with
the line diagnostics show."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.speed_model import cached_speed_table
from feeder_ros.drive.speed_model_source import SpeedModelSource, build_speed_model
from feeder_ros.identification.rational_fit import IdentificationError, RationalModel
from feeder_ros.identification.speed_model_file import (
    ModelEntry,
    SpeedModelFile,
    identified_speed_table,
    save_speed_model,
)
from feeder_ros.physics.parameters import FeederParameters

LIMITS = DriveLimits(min_frequency_hz=10.0, max_frequency_hz=60.0)


def test_disabled_gives_no_model() -> None:
    model, line = build_speed_model(
        SpeedModelSource(enabled=False, file="ignored.yaml"), FeederParameters(), LIMITS
    )
    assert model is None
    assert line == "disabled"


def test_physics_table_is_computed_then_loaded_from_the_cache(tmp_path: Path) -> None:
    source = SpeedModelSource(
        cache_dir=str(tmp_path), frequency_steps=5, amplitude_steps=3, duration_s=0.5
    )
    plant = FeederParameters()
    model, line = build_speed_model(source, plant, LIMITS)
    [cached] = tmp_path.glob("speed_table_*.npz")
    low, high = model.reachable_range()  # type: ignore[union-attr]
    assert line == f"computed table {cached.name}, {low:.4g}..{high:.4g} m/s"
    again, line_again = build_speed_model(source, plant, LIMITS)
    assert line_again == f"loaded table {cached.name}, {low:.4g}..{high:.4g} m/s"
    reference, _, _ = cached_speed_table(plant, LIMITS, tmp_path, 5, 3, 0.5)
    np.testing.assert_array_equal(again.speeds_mps, reference.speeds_mps)  # type: ignore[union-attr]


def test_a_model_file_gives_the_identified_speeds_for_the_plants_part_mass(
    tmp_path: Path,
) -> None:
    def entry(amplitude_percent: float, mass_kg: float, gain: float) -> ModelEntry:
        model = RationalModel(gain, (), (-2.0 * np.pi * 40.0,))
        return ModelEntry(amplitude_percent, amplitude_percent, mass_kg, (20.0, 50.0), 90.0, model)

    model_file = SpeedModelFile(
        100.0,
        (
            entry(30.0, 0.05, 0.3),
            entry(60.0, 0.05, 0.2),
            entry(30.0, 0.1, 0.9),
            entry(60.0, 0.1, 0.8),
        ),
        "test sweep",
    )
    path = tmp_path / "speed_model.yaml"
    save_speed_model(path, model_file)
    source = SpeedModelSource(file=str(path), frequency_steps=7)
    model, line = build_speed_model(source, FeederParameters(part_mass_kg=0.1), LIMITS)
    expected = identified_speed_table(model_file, LIMITS, part_mass_kg=0.1, frequency_steps=7)
    np.testing.assert_array_equal(model.speeds_mps, expected.speeds_mps)  # type: ignore[union-attr]
    low, high = expected.reachable_range()
    assert line == f"identified model speed_model.yaml (4 fits), {low:.4g}..{high:.4g} m/s"
    assert not list(tmp_path.glob("speed_table_*"))  # no physics table was made


def test_a_file_that_is_not_a_speed_model_is_refused_with_its_name(tmp_path: Path) -> None:
    path = tmp_path / "notes.yaml"
    path.write_text("hello: world\n")
    with pytest.raises(IdentificationError, match=re.escape("notes.yaml")):
        build_speed_model(SpeedModelSource(file=str(path)), FeederParameters(), LIMITS)
