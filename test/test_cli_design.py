"""``feeder design`` in-process: the report files read back, the parameter file loads, refusals."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import yaml

from feeder_ros.cli.main import main
from feeder_ros.cli.sim import load_parameters
from feeder_ros.design.sensitivity import SENSITIVITY_COLUMNS
from feeder_ros.design.space import DESIGN_VARIABLES
from feeder_ros.physics.parameters import PARAMETER_SPECS, FeederParameters

SMALL = [
    "--seed", "3", "--population", "14", "--generations", "4", "--map-points", "4",
    "--robust-generations", "2",
]  # fmt: skip


def test_end_to_end_writes_the_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    assert main(["design", *SMALL, "--output", str(out)]) == 0
    captured = capsys.readouterr()
    printed = captured.out

    record = json.loads((out / "design.json").read_text(encoding="utf-8"))
    assert record["objective"] == "max-speed"
    assert record["seed"] == 3
    assert record["feasible"] is True
    optimum, reference = record["optimum"], record["reference"]
    assert optimum["feasible"] is True
    assert optimum["in_set_s"] is True
    assert optimum["forward_margin"] >= record["conditions"]["required_margin"] - 1e-9
    assert optimum["speed_mps"] > reference["speed_mps"]
    assert reference["design"]["drive_frequency_hz"] == 29.6  # the case study ...
    assert reference["parameters"]["damping_ns_per_m"] == 200.0  # ... on the same damped plant
    assert record["plant"]["damping_ns_per_m"] == 200.0
    assert set(optimum["constraints"]) == {
        "forward_stick", "backward_slip", "stiffness_ratio", "slenderness", "stroke",
    }  # fmt: skip
    assert record["evaluations"] == record["history"][-1][0]
    assert -record["objective_value"] == optimum["speed_mps"]
    # the summary prints the same numbers, case study beside the optimum
    speed_line = next(line for line in printed.splitlines() if line.startswith("part speed"))
    assert speed_line.split()[-2:] == [
        f"{reference['speed_mps'] * 1e3:.4g}",
        f"{optimum['speed_mps'] * 1e3:.4g}",
    ]
    assert f"{record['evaluations']} designs evaluated" in printed
    assert "sensitivity at the optimum" in printed
    # the optimum as built: the tolerances' draws, in the terminal and in design.json
    built = record["robustness"]
    assert built["samples"] == 64
    assert set(built["probability_by_condition"]) == set(optimum["constraints"])
    assert f"every condition met in {100 * built['probability_all_conditions']:.0f} %" in printed
    assert built["robust"] == (built["probability_all_conditions"] >= 0.95)
    # this optimum sits on the forward-stick edge: said on stderr, with the way out
    assert built["robust"] is False
    assert (
        f"the optimum meets every condition in only {100 * built['probability_all_conditions']:.0f}"
        " % of the plants within the tolerances (a robust design: >= 95 %): it works near its "
        "nominal values only; the robust design above holds its conditions" in captured.err
    )

    # the parameter file: the simulator's ros__parameters, loading back to the optimum
    params_file = out / "optimum_params.yaml"
    document = yaml.safe_load(params_file.read_text(encoding="utf-8"))
    values = document["/**/platform_simulator"]["ros__parameters"]
    params = FeederParameters.from_mapping(values)
    assert params == FeederParameters.from_mapping(optimum["parameters"])
    for name in DESIGN_VARIABLES:
        assert getattr(params, name) == optimum["design"][name]
    assert load_parameters(params_file) == params  # what `feeder sim --config` reads
    for name, value in values.items():  # the node declares these types: a DOUBLE must be a float
        assert type(value) is PARAMETER_SPECS[name].kind, name
    assert set(values) == set(PARAMETER_SPECS)

    # the robust optimum: printed, in design.json, as parameters that load back
    robust = record["robust"]
    assert robust["best"]["share_lower_bound"] >= robust["probability"] == 0.95
    assert "robust design (every condition with probability >= 0.95)" in printed
    quantile = robust["best"]["speed_quantile_mps"]
    assert f"speed: {1e3 * quantile:.3g} mm/s or more in 95 % of the built feeders" in printed
    robust_params = load_parameters(out / "robust_params.yaml")
    for name, value in robust["best"]["variables"].items():
        assert getattr(robust_params, name) == value
    assert quantile < optimum["speed_mps"]  # the price of holding the conditions when built
    # ... assessed as the optimum is: every condition in every draw, within the tolerances at least
    as_built = robust["as_built"]
    assert as_built["robust"] is True
    assert set(as_built["probability_by_condition"].values()) == {1.0}
    assert (
        1.0
        <= as_built["largest_tolerance_multiple"]
        <= as_built["largest_tolerance_multiple_tried"]
    )
    assert as_built["speed_quantiles_mps"]["p5"] >= quantile * (1 - 1e-12)
    assert "the robust design as built: 64 plants drawn" in printed

    with (out / "sensitivity.csv").open(newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert tuple(rows[0]) == SENSITIVITY_COLUMNS
    assert [r["variable"] for r in rows] == list(DESIGN_VARIABLES)
    for row in rows:
        assert float(row["speed_mps"]) == optimum["speed_mps"]
        assert float(row["forward_margin"]) == optimum["forward_margin"]
        assert row["feasible_minus"] in ("0", "1")
    for name in ("design_convergence.png", "design_speed_map.png", "design_robust_map.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_min_force_and_fixed_plant_parameter(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "force"
    code = main(
        ["design", *SMALL, "--objective", "min-force", "--target-speed", "0.003",
         "--set", "static_friction=0.25", "--output", str(out)]
    )  # fmt: skip
    record = json.loads((out / "design.json").read_text(encoding="utf-8"))
    assert code == (0 if record["feasible"] else 1)
    assert record["objective"] == "min-force"
    assert record["target_speed_mps"] == 0.003
    assert record["plant"]["static_friction"] == 0.25
    assert record["optimum"]["stick_limit_mps2"] == pytest.approx(0.25 * 9.81)
    assert record["objective_value"] == record["optimum"]["design"]["drive_amplitude_n"]
    if record["feasible"]:
        assert record["optimum"]["speed_mps"] >= 0.003
        assert record["optimum"]["constraints"]["target_speed"] >= 0.0
    printed = capsys.readouterr()
    assert "target 3 mm/s" in printed.out
    assert "the robust search covers max-speed" in printed.err
    assert record["robust"] is None
    assert not (out / "robust_params.yaml").exists()


def test_no_design_in_set_s_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    space = tmp_path / "weak.yaml"
    # far too little force for any backward slip: set S cannot be met
    space.write_text(
        "variables: {drive_amplitude_n: [0.01, 0.02], drive_frequency_hz: [20, 40]}\n",
        encoding="utf-8",
    )
    code = main(["design", *SMALL, "--space", str(space)])
    captured = capsys.readouterr()
    assert code == 1
    assert "no evaluated design meets every condition" in captured.err
    assert "meets every condition" in captured.out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--objective", "min-force"], "--objective min-force needs --target-speed"),
        (["--target-speed", "0.01"], "--target-speed is for --objective min-force"),
        (["--set", "drive_frequency_hz=30"], "drive_frequency_hz is searched"),
        (["--set", "static_friction=-1"], "static_friction=-1.0 must be > 0"),
        (["--preset", "gentle"], "presets in this file: mismatched, realistic"),
        (["--space", "/nonexistent/design.yaml"], "--space /nonexistent/design.yaml: no such file"),
    ],
)
def test_refusals(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", *argv]) == 2
    assert message in capsys.readouterr().err


def test_bad_space_file_names_the_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    space = tmp_path / "bad.yaml"
    space.write_text("variables: {plate_count: [1, 2.5]}\n", encoding="utf-8")
    assert main(["design", "--space", str(space)]) == 2
    err = capsys.readouterr().err
    assert f"{space}: variables.plate_count: upper bound 2.5 is not an integer" in err
