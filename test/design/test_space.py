"""Design space and design file: order, integrality, vector <-> parameters, and the refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from feeder_ros.design.space import (
    DESIGN_VARIABLES,
    DesignError,
    DesignSpace,
    DesignVariable,
    load_design_config,
)
from feeder_ros.design.stick_slip_conditions import ConditionLimits, EvaluationWindow
from feeder_ros.physics.parameters import FeederParameters

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "config" / "design.yaml"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "design.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_variables_in_canonical_order_with_integrality() -> None:
    space = DesignSpace.from_mapping(
        {"drive_amplitude_n": [1, 50], "plate_count": [1, 3], "forward_length_m": [0.02, 0.08]}
    )
    assert space.names == ("forward_length_m", "plate_count", "drive_amplitude_n")
    np.testing.assert_array_equal(space.lower, [0.02, 1.0, 1.0])
    np.testing.assert_array_equal(space.upper, [0.08, 3.0, 50.0])
    np.testing.assert_array_equal(space.integrality, [False, True, False])
    assert space.variables[1].unit == "1"


def test_vector_to_parameters_and_back() -> None:
    space = DesignSpace.from_mapping({v: [1.0, 2.0] for v in ("plate_count",)} | {
        "forward_length_m": [0.02, 0.08], "drive_frequency_hz": [10.0, 60.0],
    })  # fmt: skip
    plant = FeederParameters(damping_ns_per_m=200.0, static_friction=0.3)
    params = space.to_parameters([0.04, 1.6, 42.5], plant)
    assert params.forward_length_m == 0.04
    assert params.plate_count == 2  # rounded to the integer
    assert isinstance(params.plate_count, int)
    assert params.drive_frequency_hz == 42.5
    # everything else is the plant's
    assert params.damping_ns_per_m == 200.0
    assert params.static_friction == 0.3
    assert params.backward_length_m == plant.backward_length_m
    np.testing.assert_array_equal(space.vector(params), [0.04, 2.0, 42.5])
    assert space.contains([0.04, 2.0, 42.5])
    assert not space.contains([0.01, 2.0, 42.5])
    with pytest.raises(DesignError, match="design vector has 2 values; the space has 3"):
        space.to_parameters([0.04, 2.0], plant)


def test_shipped_design_file_holds_the_case_study() -> None:
    config = load_design_config(SHIPPED)
    assert config.space.names == DESIGN_VARIABLES
    case = config.reference_parameters(FeederParameters())
    assert case == FeederParameters(drive_amplitude_n=40.0)  # the paper's case study, A = 40 N
    assert config.space.contains(config.space.vector(case))
    assert config.limits == ConditionLimits(
        required_margin=0.05, min_stiffness_ratio=1.5, min_slenderness=5.0, max_stroke_m=0.005
    )
    assert config.window == EvaluationWindow(settle_s=1.0, window_s=1.0, margin_rate_hz=20000.0)


@pytest.mark.parametrize(
    ("variables", "message"),
    [
        ("{stiffness_n: [1, 2]}", r"variables\.stiffness_n: unknown design variable 'stiffness_n'"),
        (
            "{forward_length_m: [0.08, 0.03]}",
            r"lower bound 0\.08 must be below the upper bound 0\.03",
        ),
        ("{forward_length_m: [0.05, 0.05]}", r"0\.05 must be below the upper bound 0\.05 \(to fix"),
        (
            "{forward_length_m: [.nan, 0.1]}",
            r"variables\.forward_length_m: lower bound nan is not finite",
        ),
        ("{drive_amplitude_n: [1, .inf]}", r"drive_amplitude_n: upper bound inf is not finite"),
        ("{plate_count: [1.5, 4]}", r"variables\.plate_count: lower bound 1\.5 is not an integer"),
        ("{plate_count: [1, 3.2]}", r"variables\.plate_count: upper bound 3\.2 is not an integer"),
        (
            "{plate_angle_deg: [60, 95]}",
            r"plate_angle_deg: upper bound: plate_angle_deg=95\.0 deg must be <= 89\.9",
        ),
        (
            "{plate_thickness_m: [-0.001, 0.01]}",
            r"lower bound: plate_thickness_m=-0\.001 m must be > 0",
        ),
        ("{plate_thickness_m: [0.001, '0.01']}", r"upper bound '0\.01' is not a number"),
        (
            "{plate_thickness_m: 0.005}",
            r"variables\.plate_thickness_m: expected \[lower, upper\], got 0\.005",
        ),
        ("{}", r"no design variable given"),
    ],
)  # fmt: skip
def test_bad_variables_are_refused_naming_key_and_value(
    tmp_path: Path, variables: str, message: str
) -> None:
    path = _write(tmp_path, f"variables: {variables}\n")
    with pytest.raises(DesignError, match=message) as caught:
        load_design_config(path)
    assert str(caught.value).startswith(f"{path}: ")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("bounds: {}", r"unknown section bounds; known: variables, conditions"),
        ("conditions: {required_margin: -0.1}", r"conditions\.required_margin=-0\.1 must be >= 0"),
        ("conditions: {required_margin: 1.0}", r"conditions\.required_margin=1\.0 must be < 1"),
        (
            "conditions: {max_stroke: 0.01}",
            r"conditions: unknown key max_stroke; known: required_margin",
        ),
        ("evaluation: {window_s: 0}", r"evaluation\.window_s=0 must be > 0"),
        ("evaluation: {settle_s: .nan}", r"evaluation\.settle_s=nan is not finite"),
        ("evaluation: {window_s: 0.01, margin_rate_hz: 100}", r"fewer than 10 samples"),
        ("reference: {plate_colour: 3}", r"reference: unknown parameter plate_colour"),
        ("reference: {plate_count: 1.5}", r"reference: plate_count=1\.5 is not an integer"),
    ],
)  # fmt: skip
def test_bad_sections_are_refused(tmp_path: Path, extra: str, message: str) -> None:
    path = _write(tmp_path, f"variables: {{plate_count: [1, 3]}}\n{extra}\n")
    with pytest.raises(DesignError, match=message):
        load_design_config(path)


def test_missing_variables_and_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(DesignError, match="no 'variables' section"):
        load_design_config(_write(tmp_path, "conditions: {}\n"))
    with pytest.raises(DesignError, match="not valid YAML"):
        load_design_config(_write(tmp_path, "variables: [\n"))
    path = _write(tmp_path, "")
    with pytest.raises(DesignError) as empty:
        load_design_config(path)
    expected = f"{path}: expected sections variables, conditions, evaluation, reference, tolerances"
    assert str(empty.value) == expected  # the file named once
    path.write_bytes(b"\xff\xfe")
    with pytest.raises(DesignError, match=r"design.yaml: not UTF-8 text \(invalid start byte"):
        load_design_config(path)


def test_variable_refusals_directly() -> None:
    with pytest.raises(DesignError, match=r"unknown design variable 'damping_ns_per_m'"):
        DesignVariable("damping_ns_per_m", 0.0, 100.0)
    with pytest.raises(DesignError, match="plate_count given more than once"):
        DesignSpace((DesignVariable("plate_count", 1, 2), DesignVariable("plate_count", 1, 3)))
    with pytest.raises(DesignError, match=r"lower bound True is not a number"):
        DesignVariable("plate_count", True, 3)
