"""Speed model file: YAML round trip, refusals naming file/field/value, atomic save, and the speed
table the drive interface's target-speed mode uses (allowed frequencies, forbidden bands)."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.identification.rational_fit import (
    IdentificationError,
    RationalModel,
    fit_rational,
)
from feeder_ros.identification.speed_model_file import (
    ModelEntry,
    SpeedModelFile,
    identified_speed_table,
    load_speed_model,
    save_speed_model,
)

FULL_SCALE_N = 100.0
POLE_RAD_S = 2.0 * math.pi * 40.0  # G(s) = g / (s + a): |G(j w)| = g / sqrt(w^2 + a^2)
BAND = (38.0, 58.0)


def first_order(gain: float) -> RationalModel:
    return RationalModel(gain, (), (-POLE_RAD_S,))


def first_order_speed(gain: float, frequency_hz: np.ndarray, amplitude_n: float) -> np.ndarray:
    omega = 2.0 * math.pi * frequency_hz
    return gain / np.sqrt(omega**2 + POLE_RAD_S**2) * amplitude_n


def entry(amplitude_percent: float, mass_kg: float, gain: float) -> ModelEntry:
    force = amplitude_percent / 100.0 * FULL_SCALE_N
    return ModelEntry(amplitude_percent, force, mass_kg, BAND, 93.5, first_order(gain))


# gains differ per entry (and not monotonically in amplitude), so the column order is checked
GAINS = {(0.031, 35.0): 0.30, (0.031, 47.0): 0.20, (0.031, 41.0): 0.25, (0.06, 41.0): 0.4}
MODEL_FILE = SpeedModelFile(
    FULL_SCALE_N,
    (
        *(entry(amplitude, mass, gain) for (mass, amplitude), gain in GAINS.items()),
        entry(47.0, 0.06, 0.35),
    ),
    "test sweep",
)


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    path = tmp_path / "speed_model.yaml"
    save_speed_model(path, MODEL_FILE)
    return path


Change = Callable[[dict[str, Any]], object]


def edit(path: Path, change: Change) -> None:
    """Rewrite the YAML file after ``change(document)``."""
    document = yaml.safe_load(path.read_text())
    change(document)
    path.write_text(yaml.safe_dump(document, sort_keys=False))


# ------------------------------------------------------------------------------ file round trip


def test_save_and_load_round_trip(saved: Path) -> None:
    loaded = load_speed_model(saved)
    assert loaded == MODEL_FILE
    document = yaml.safe_load(saved.read_text())
    assert document["format"] == "feeder_ros/identified_speed_model"
    assert document["version"] == 1
    assert document["units"]["speed"] == "m/s"
    assert document["entries"][0]["model"] == {
        "gain": 0.30,
        "zeros": [],
        "poles": [[-POLE_RAD_S, 0.0]],
    }
    assert list(saved.parent.iterdir()) == [saved]  # no temporary file left behind


def test_entry_from_a_fit() -> None:
    f = np.linspace(40.0, 50.0, 21)
    fit = fit_rational(f, first_order_speed(0.3, f, 41.0), 41.0, 0, 1)
    made = ModelEntry.from_fit(fit, 41.0, 0.031)
    assert made.frequency_range_hz == (40.0, 50.0)
    assert made.amplitude_n == 41.0
    assert made.fit_percent == fit.fit_percent
    assert made.model.poles[0] == pytest.approx(-POLE_RAD_S, rel=1e-6)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d["entries"][1].pop("amplitude_n"), r"missing field entries\[1\]\.amplitude_n"),
        (lambda d: d.pop("full_scale_force_n"), "missing field full_scale_force_n"),
        (lambda d: d.update(version=2), "version=2 is not supported"),
        (lambda d: d.update(format="other"), "format='other' is not"),
        (lambda d: d["units"].update(speed="cm/s"), "units.speed='cm/s' is not 'm/s'"),
        (
            lambda d: d["entries"][0].update(fit_percent=math.nan),
            r"entries\[0\]\.fit_percent=nan is not finite",
        ),
        (
            lambda d: d["entries"][2]["model"].update(poles=[[5.0, 0.0]]),
            r"entries\[2\]\.model: poles\[0\] = \(5\+0j\) is not stable",
        ),
        (
            lambda d: d["entries"][0]["model"].update(gain="big"),
            r"entries\[0\]\.model: gain='big' is not a number",
        ),
        (
            lambda d: d["entries"][3].update(amplitude_n=12.0),
            r"entries\[3\]\.amplitude_n=12\.0 N does not match amplitude_percent=41 %",
        ),
        (
            lambda d: d["entries"][1].update(frequency_range_hz=[58.0, 38.0]),
            r"entries\[1\]: frequency_range_hz=\[58\.0, 38\.0\] needs 0 < low < high",
        ),
        (
            lambda d: d["entries"][0].update(amplitude_percent=150.0, amplitude_n=150.0),
            r"entries\[0\]: amplitude_percent=150\.0 must be in \(0, 100\]",
        ),
        (lambda d: d.update(entries=[]), "entries is empty"),
        (
            lambda d: d["entries"].append(d["entries"][0]),
            r"entries\[0\] and entries\[5\] are both for part_mass_kg=0\.031",
        ),
    ],
)
def test_load_refuses_a_bad_file_naming_file_field_and_value(
    saved: Path, change: Change, message: str
) -> None:
    edit(saved, change)
    with pytest.raises(IdentificationError, match=re.escape(str(saved)) + ": " + message):
        load_speed_model(saved)


def test_load_refuses_corrupt_truncated_empty_and_missing_files(saved: Path) -> None:
    text = saved.read_text()
    saved.write_text("entries: [ {amplitude_percent: 41\n")
    with pytest.raises(IdentificationError, match=re.escape(str(saved)) + ": not valid YAML"):
        load_speed_model(saved)
    cut = text.index("- amplitude_percent: 47.0")  # the file ends after two entries
    saved.write_text(text[: cut + len("- amplitude_percent: 47.0\n  amplitude_n: 47")])
    with pytest.raises(IdentificationError, match=r"missing field entries\[1\]\.part_mass_kg"):
        load_speed_model(saved)
    saved.write_text("")
    with pytest.raises(IdentificationError, match="the file is empty"):
        load_speed_model(saved)
    missing = saved.parent / "absent.yaml"
    with pytest.raises(IdentificationError, match=r"absent\.yaml: cannot read"):
        load_speed_model(missing)


def test_failed_save_leaves_the_existing_file_untouched(
    saved: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = saved.read_bytes()
    other = SpeedModelFile(FULL_SCALE_N, MODEL_FILE.entries[:2], "another sweep")

    def disk_full(descriptor: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", disk_full)
    with pytest.raises(OSError, match="No space left"):
        save_speed_model(saved, other)
    monkeypatch.undo()
    assert saved.read_bytes() == before
    assert list(saved.parent.iterdir()) == [saved]
    # a model that does not validate (bypassing the constructor) is refused before any write
    broken = SpeedModelFile(FULL_SCALE_N, (entry(41.0, 0.031, 0.25), entry(47.0, 0.031, 0.2)))
    object.__setattr__(broken.entries[0].model, "gain", math.nan)
    with pytest.raises(IdentificationError, match=r"not saved.*entries\[0\]\.model: gain=nan"):
        save_speed_model(saved, broken)
    assert saved.read_bytes() == before
    save_speed_model(saved, other)  # and a good save replaces it
    assert load_speed_model(saved) == other


def test_model_file_refuses_inconsistent_contents() -> None:
    with pytest.raises(IdentificationError, match=r"full_scale_force_n=0\.0 must be > 0"):
        SpeedModelFile(0.0, MODEL_FILE.entries)
    with pytest.raises(IdentificationError, match="entries is empty"):
        SpeedModelFile(FULL_SCALE_N, ())
    with pytest.raises(IdentificationError, match=r"amplitude_n=-1\.0 must be > 0"):
        ModelEntry(41.0, -1.0, 0.031, BAND, 90.0, first_order(1.0))
    with pytest.raises(IdentificationError, match=r"fit_percent=101\.0 cannot exceed 100"):
        ModelEntry(41.0, 41.0, 0.031, BAND, 101.0, first_order(1.0))


# ------------------------------------------------------------------------------ the speed table


def test_table_speeds_are_the_model_at_allowed_frequencies() -> None:
    limits = DriveLimits(forbidden_bands_hz=((45.0, 50.0),))
    table = identified_speed_table(MODEL_FILE, limits, part_mass_kg=0.031, frequency_steps=41)
    np.testing.assert_array_equal(table.amplitudes_percent, [35.0, 41.0, 47.0])
    f = table.frequencies_hz
    assert f.min() == 38.0
    assert f.max() == 58.0
    assert not np.any((f > 45.0) & (f < 50.0))  # nothing inside the forbidden band ...
    assert 45.0 in f  # ... its edges stand in for it
    assert 50.0 in f
    assert all(limits.forbidden_band_of(float(x)) is None for x in f)
    assert np.all(np.diff(f) > 0.0)
    for column, (amplitude, gain) in enumerate([(35.0, 0.30), (41.0, 0.25), (47.0, 0.20)]):
        expected = first_order_speed(gain, f, amplitude / 100.0 * FULL_SCALE_N)
        np.testing.assert_allclose(table.speeds_mps[:, column], expected, rtol=1e-12)


def test_choose_on_the_identified_table_gives_the_requested_speed() -> None:
    limits = DriveLimits(forbidden_bands_hz=((45.0, 50.0),))
    table = identified_speed_table(MODEL_FILE, limits, part_mass_kg=0.031)
    low, high = table.reachable_range()
    target = 0.5 * (low + high)
    choice = table.choose(target)
    assert choice is not None
    assert choice.predicted_speed_mps == target
    assert limits.forbidden_band_of(choice.frequency_hz) is None
    assert choice.frequency_hz in table.frequencies_hz
    assert 35.0 <= choice.amplitude_percent <= 47.0
    # the model's prediction at that setting, linear between the identified amplitudes
    f = np.asarray([choice.frequency_hz])
    nodes = [(35.0, 0.30), (41.0, 0.25), (47.0, 0.20)]
    speeds = [first_order_speed(g, f, a / 100 * FULL_SCALE_N)[0] for a, g in nodes]
    predicted = np.interp(choice.amplitude_percent, [a for a, _ in nodes], speeds)
    assert predicted == pytest.approx(target, rel=1e-12)
    assert table.choose(high * 1.01) is None


def test_table_uses_the_nearest_mass_and_the_drive_amplitude_limit() -> None:
    limits = DriveLimits()
    heavy = identified_speed_table(MODEL_FILE, limits, part_mass_kg=0.05)
    np.testing.assert_array_equal(heavy.amplitudes_percent, [41.0, 47.0])
    expected = first_order_speed(0.4, heavy.frequencies_hz, 41.0)
    np.testing.assert_allclose(heavy.speeds_mps[:, 0], expected, rtol=1e-12)
    light = identified_speed_table(MODEL_FILE, limits, part_mass_kg=0.045)  # 14 g vs 15 g away
    np.testing.assert_array_equal(light.amplitudes_percent, [35.0, 41.0, 47.0])
    capped = identified_speed_table(
        MODEL_FILE, DriveLimits(max_amplitude_percent=45.0), part_mass_kg=0.031
    )
    np.testing.assert_array_equal(capped.amplitudes_percent, [35.0, 41.0])
    single_mass = SpeedModelFile(FULL_SCALE_N, MODEL_FILE.entries[:3])
    assert identified_speed_table(single_mass, limits).amplitudes_percent.size == 3


@pytest.mark.parametrize(
    ("limits", "mass", "message"),
    [
        (
            DriveLimits(min_frequency_hz=100.0),
            0.031,
            "38-58 Hz does not overlap the drive's 100-300",
        ),
        (
            DriveLimits(forbidden_bands_hz=((30.0, 70.0),)),
            0.031,
            r"no allowed frequency inside the identified range 38-58 Hz \(forbidden bands: 30-70",
        ),
        (DriveLimits(max_amplitude_percent=40.0), 0.031, r"amplitudes 35, 47, 41 % identified, 1 "),
        (DriveLimits(), None, "part masses 0.031, 0.06 kg: part_mass_kg must say which"),
        (DriveLimits(), -1.0, r"part_mass_kg=-1\.0 must be > 0"),
    ],
)
def test_table_refusals(limits: DriveLimits, mass: float | None, message: str) -> None:
    with pytest.raises(IdentificationError, match=message):
        identified_speed_table(MODEL_FILE, limits, part_mass_kg=mass)


def test_table_refuses_ranges_without_a_common_part() -> None:
    apart = SpeedModelFile(
        FULL_SCALE_N,
        (
            ModelEntry(35.0, 35.0, 0.031, (38.0, 45.0), 90.0, first_order(0.3)),
            ModelEntry(41.0, 41.0, 0.031, (50.0, 58.0), 90.0, first_order(0.3)),
        ),
    )
    with pytest.raises(IdentificationError, match="35, 41 % have no common part"):
        identified_speed_table(apart, DriveLimits())
