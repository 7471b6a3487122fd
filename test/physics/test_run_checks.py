"""Warnings about likely unit mistakes and the note on a run without slip
(feeder_ros.physics.run_checks)."""

from __future__ import annotations

import re

import numpy as np

from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.run_checks import likely_unit_mistakes, no_slip_note
from feeder_ros.physics.simulation import PartSpec, simulate

CASE = FeederParameters()  # the paper's case study: f_n 32.9 / 6.3 Hz, f_d 29.6 Hz


def test_a_plausible_drive_gives_no_warning() -> None:
    assert likely_unit_mistakes(CASE, 1000.0) == []
    assert likely_unit_mistakes(CASE.with_changes(drive_frequency_hz=300.0), 1000.0) == []


def test_a_frequency_far_above_resonance_is_named_with_its_rad_s_reading() -> None:
    # 29.6 Hz typed as rad/s (186) is under 10x the highest natural frequency: not warned
    assert likely_unit_mistakes(CASE.with_changes(drive_frequency_hz=186.0), 1000.0) == []
    params = CASE.with_changes(drive_frequency_hz=400.0)
    [warning] = likely_unit_mistakes(params, 1000.0)
    assert warning.startswith("drive_frequency_hz=400 is 12x the carrier's highest natural")
    assert "(400 rad/s would be 63.66 Hz)" in warning


def test_a_frequency_above_half_the_output_rate_says_what_rate_to_use() -> None:
    params = CASE.with_changes(drive_frequency_hz=60.0)
    [warning] = likely_unit_mistakes(params, 100.0)
    assert warning == (
        "drive_frequency_hz=60 is above half the output rate (--rate 100): the samples alias "
        "the vibration; use --rate 1200 or more"
    )


def test_the_no_slip_note_suggests_an_amplitude_that_does_slip() -> None:
    parts = [PartSpec(0.0)]
    quiet = simulate(CASE, 1.0, 1000.0, parts=parts)
    assert float(np.nanmean(quiet.slip_fraction())) == 0.0
    note = no_slip_note(CASE, quiet.carrier_a_mps2)
    peak = float(np.max(np.abs(quiet.carrier_a_mps2)))
    assert f"peak acceleration {peak:.3g} m/s^2" in note
    assert f"L = mu_s*g*kappa = {CASE.stick_limit_mps2:.3g} m/s^2" in note
    suggested = float(re.search(r"drive_amplitude_n=([0-9.e+-]+)", note).group(1))  # type: ignore[union-attr]
    assert suggested > CASE.drive_amplitude_n
    slipping = simulate(CASE.with_changes(drive_amplitude_n=suggested), 1.0, 1000.0, parts=parts)
    assert float(np.nanmean(slipping.slip_fraction())) > 0.1


def test_without_a_drive_the_note_asks_for_one() -> None:
    note = no_slip_note(CASE.with_changes(drive_amplitude_n=0.0), np.zeros(10))
    assert note.endswith("To see slip, give the drive an amplitude (--set drive_amplitude_n=...)")
