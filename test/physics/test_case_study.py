"""Section 4's checkable facts (MODEL-NOTES) and the Fig. 8 equivalents."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from feeder_ros.physics.case_study import (
    case_study_facts,
    case_study_facts_from_result,
    plot_case_study,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import FeederSimulator, simulate


def test_natural_frequencies_need_the_corrected_part_mass() -> None:
    facts = case_study_facts(0.4, duration_s=0.05)
    assert facts.forward_natural_frequency_hz == pytest.approx(32.93, abs=0.005)
    assert facts.backward_natural_frequency_hz == pytest.approx(6.34, abs=0.005)
    printed = FeederParameters(part_mass_kg=50.0)  # the paper's printed M_p: far from 33/6.3 Hz
    assert printed.forward_natural_frequency_hz < 15.0


def test_small_amplitude_part_follows_the_carrier() -> None:
    facts = case_study_facts(0.4, duration_s=2.0)
    assert facts.peak_carrier_acceleration_mps2 < facts.stick_limit_mps2
    assert not facts.slips
    assert facts.first_slip_onset_s is None


def test_large_amplitude_slips_both_ways_from_about_3_ms() -> None:
    facts = case_study_facts(40.0, duration_s=0.1)
    assert facts.slips
    assert facts.slips_both_ways
    assert facts.first_slip_onset_s == pytest.approx(0.003, abs=0.0005)
    # the onset is where the carrier acceleration reaches the threshold mu_s*g
    onset = facts.first_slip_onset_s
    assert onset is not None
    at = FeederSimulator(FeederParameters(drive_amplitude_n=40.0)).advance(0.01, [onset])
    assert at.carrier_a_mps2[0] == pytest.approx(0.2 * 9.81, rel=1e-9)
    # homogeneity: the carrier at 40 N is 100 times the one at 0.4 N, the parts are not
    assert facts.peak_carrier_acceleration_mps2 == pytest.approx(
        100 * case_study_facts(0.4, duration_s=0.1).peak_carrier_acceleration_mps2, rel=1e-9
    )


def test_facts_from_a_result_without_parts() -> None:
    params = FeederParameters(drive_amplitude_n=40.0)
    facts = case_study_facts_from_result(params, simulate(params, 0.05, 1000.0, parts=()))
    assert not facts.slips
    assert facts.peak_carrier_acceleration_mps2 > facts.stick_limit_mps2


def test_fig8_equivalents_are_written(tmp_path: Path) -> None:
    paths = plot_case_study(tmp_path, duration_s=1.0)
    assert [p.name for p in paths] == [
        f"A{a}N_{name}.png"
        for a in ("0.4", "40")
        for name in ("carrier_displacement", "phase_portrait", "first_40ms", "parts_over_run")
    ]
    for path in paths:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        image = imread(path)
        assert image.shape[0] > 300
        assert image.shape[1] > 500
        assert float(np.std(image)) > 0.01  # not blank
