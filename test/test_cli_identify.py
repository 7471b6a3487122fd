"""``feeder identify`` in-process: a simulator sweep fitted end to end (files read back, the fit
beats the paper's 63 %, the model file loads), the CSV and bag sources, and bad data or plans
refused with the reason (exit status 2)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from identification.test_bag_sweep import write_sweep_bag

from feeder_ros.cli.identify import default_plan_path
from feeder_ros.cli.main import main
from feeder_ros.cli.sim import default_config_path, load_parameters
from feeder_ros.identification.offline_sweep import offline_sweep
from feeder_ros.identification.rational_fit import RationalModel
from feeder_ros.identification.sweep import SweepPlan, SweepResult

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SMALL = ["--amplitudes", "40", "--masses", "0.031", "--orders", "1/2,1/4"]


def test_sim_sweep_is_fitted_and_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, model_file = tmp_path / "out", tmp_path / "speed_model.yaml"
    code = main(["identify", *SMALL, "--output", str(out), "--model-out", str(model_file)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "sweep: 18 points, 18 usable, source sim" in printed
    assert "40 %   31 g     18" in printed
    assert sorted(p.name for p in out.iterdir()) == [
        ".feeder-outputs",
        "fig10.png",
        "fig9.png",
        "fit.json",
        "sweep.csv",
    ]

    # the sweep: the default plan's band on the realistic preset, exactly the offline source's
    sweep = SweepResult.read_csv(out / "sweep.csv")
    plan = SweepPlan(
        frequencies_hz=tuple(19.0 + 0.5 * k for k in range(18)),
        amplitudes_percent=(40.0,),
        part_masses_kg=(0.031,),
        settle_s=1.0,
        window_s=3.0,
    )
    expected = offline_sweep(load_parameters(default_config_path(), preset="realistic"), plan)
    assert [p.speed_mps for p in sweep.points] == [p.speed_mps for p in expected.points]
    assert [p.frequency_hz for p in sweep.points] == list(plan.frequencies_hz)

    # the fit: beats the paper's 63 %, peak at the resonance near 20.5 Hz, both orders scored
    document = json.loads((out / "fit.json").read_text())
    assert document["source"] == "sim"
    assert document["plant"]["preset"] == "realistic"
    assert document["plan"]["window_s"] == 3.0
    (group,) = document["groups"]
    assert group["error"] is None
    assert group["fit_percent"] > 63.0  # the paper's fit for its 31 g vehicle
    assert 20.0 < group["peak_frequency_hz"] < 21.0
    assert group["measured_peak_hz"] == 20.5
    assert [(o["zeros"], o["poles"]) for o in group["orders"]] == [(1, 2), (1, 4)]
    assert all(math.isfinite(o["holdout_fit_percent"]) for o in group["orders"])
    chosen = (group["chosen_order"]["zeros"], group["chosen_order"]["poles"])
    scores = {(o["zeros"], o["poles"]): o for o in group["orders"]}
    assert group["fit_percent"] == scores[chosen]["fit_percent"]
    # chosen on the hold-out fit (ties within 1 point go to fewer parameters)
    best_holdout = max(o["holdout_fit_percent"] for o in group["orders"])
    assert group["holdout_fit_percent"] >= best_holdout - 1.0
    assert len(group["poles"]) == chosen[1]
    assert len(group["zeros"]) == chosen[0]
    model = RationalModel.from_dict(group["model"])
    predicted = model.magnitude([p.frequency_hz for p in sweep.points]) * 40.0
    residual = [v - p.speed_mps for v, p in zip(predicted, sweep.points, strict=True)]
    rms = math.sqrt(sum(r * r for r in residual) / len(residual))
    assert rms == pytest.approx(group["residual_rms_mps"], rel=1e-9)

    for name in ("fig9.png", "fig10.png"):
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC)
        assert len(data) > 10_000

    # the speed model file for the drive interface loads back with the same model
    from feeder_ros.identification.speed_model_file import load_speed_model

    loaded = load_speed_model(model_file)
    assert loaded.full_scale_force_n == 100.0
    (entry,) = loaded.entries
    assert (entry.amplitude_percent, entry.amplitude_n, entry.part_mass_kg) == (40.0, 40.0, 0.031)
    assert tuple(entry.frequency_range_hz) == (19.0, 27.5)
    assert entry.fit_percent == pytest.approx(group["fit_percent"])
    assert entry.model.to_dict() == group["model"]

    # the CSV source fits the written sweep again: the same models
    again = tmp_path / "again"
    assert main(["identify", "--source", "csv", str(out / "sweep.csv"), "--orders", "1/2,1/4",
                 "--output", str(again)]) == 0  # fmt: skip
    refit = json.loads((again / "fit.json").read_text())
    assert refit["source"].startswith("csv ")
    assert refit["plan"] is None
    # the same models: equal responses over the band (a zero far above the band is only a gain,
    # and how the fit splits gain and zero there is round-off)
    band = np.linspace(19.0, 27.5, 200)
    first = RationalModel.from_dict(group["model"])
    second = RationalModel.from_dict(refit["groups"][0]["model"])
    assert second.order == first.order
    np.testing.assert_allclose(second.magnitude(band), first.magnitude(band), rtol=1e-6)
    assert refit["groups"][0]["fit_percent"] == pytest.approx(group["fit_percent"], abs=1e-6)

    # the same directory again without the fit: the earlier run's fit and Bode plot are removed
    # (they would contradict the new sweep), a file of the user's is not
    (again / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["identify", "--source", "csv", str(out / "sweep.csv"), "--no-fit",
                 "--output", str(again)]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert (
        f"removed 2 file(s) an earlier run wrote to {again} and this one did not: fig10.png, "
        "fit.json" in printed
    )
    assert sorted(p.name for p in again.iterdir()) == [
        ".feeder-outputs",
        "fig9.png",
        "notes.txt",
        "sweep.csv",
    ]


def test_the_default_plan_file_is_found() -> None:
    path = default_plan_path()
    assert path.name == "identify.yaml"
    assert path.is_file()


def _fails(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(["identify", *args]) == 2
    return capsys.readouterr().err


def test_bad_data_is_refused_with_the_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a single frequency: no frequency response
    err = _fails(["--frequencies", "20.5", *SMALL], capsys)
    assert "no model could be fitted" in err
    assert "a single frequency (20.5 Hz, 1 point(s))" in err
    # too few points for the orders (and their hold-out check)
    err = _fails(["--frequencies", "20:21:0.5", *SMALL], capsys)
    assert "only 3 usable point(s); the models asked for need at least 7" in err
    # NaN in a usable row of a sweep CSV
    csv = tmp_path / "sweep.csv"
    assert main(["identify", *SMALL, "--frequencies", "20:23:1", "--no-fit", "--output",
                 str(tmp_path)]) == 0  # fmt: skip
    capsys.readouterr()
    lines = csv.read_text().splitlines()
    cells = lines[2].split(",")
    cells[4] = "nan"  # speed_mps
    lines[2] = ",".join(cells)
    csv.write_text("\n".join(lines) + "\n")
    err = _fails(["--source", "csv", str(csv)], capsys)
    assert "line 3: speed_mps=nan in a usable row (ok=1)" in err
    # a field no CSV writer makes (the csv module's limit): the file is named, not a traceback
    csv.write_text(lines[0] + "\n" + '"' + "9" * 200_000 + '"\n')
    err = _fails(["--source", "csv", str(csv)], capsys)
    assert f"{csv}: cannot read: field larger than field limit" in err
    # parts running backwards only: nothing to fit (left out as the paper left them out)
    err = _fails(["--frequencies", "17:18:0.5", *SMALL], capsys)
    assert "no usable points" in err


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--amplitudes", "150"], "--amplitudes: amplitudes_percent=150.0: must lie in (0, 100]"),
        (["--frequencies", "58:38:0.5"], "--frequencies: frequencies_hz='58:38:0.5': stop is"),
        (["--orders", "3/2"], "--orders: orders='3/2': more zeros than poles"),
        (["--window", "2", "--distance", "0.085"], "give one (a window or a distance)"),
        (["--no-fit", "--model-out", "m.yaml"], "--model-out needs the fit"),
        (["--source", "bag"], "give the bag(s) of the sweep"),
        (["--source", "csv"], "give exactly one sweep CSV"),
        (["--plan", "missing.yaml"], "--plan missing.yaml: no such file"),
        (["--set", "damping_ns_per_m=-1"], "damping_ns_per_m"),
        (["--source", "live"], "2 part masses: a live sweep measures the parts that are on"),
        (["--source", "sim", "x.csv"], "--source sim takes no input files"),
        (["--source", "sim", "--measure", "truth"], "--measure is for --source live (not sim)"),
        (["--source", "csv", "x.csv", "--namespace", "/a"], "--namespace is for --source live"),
        (["--source", "csv", "x.csv", "--set", "damping_ns_per_m=3"], "--set is for --source sim"),
        (["--source", "bag", "b", "--config", "c.yaml"], "--config is for --source sim"),
        (["--source", "live", "--preset", "none"], "--preset is for --source sim"),
    ],
)
def test_bad_options_are_refused(
    args: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert needle in _fails(args, capsys)


def test_the_command_line_completes_a_plan_file_without_the_grid(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plan = tmp_path / "plan.yaml"
    plan.write_text("sweep:\n  frequencies_hz: '20, 21'\n  settle_s: 1\n  window_s: 2\n")
    args = ["identify", "--source", "sim", "--plan", str(plan), "--amplitudes", "40", "--no-fit"]
    assert main([*args, "--masses", "0.05"]) == 0
    assert "sweep: 2 points, 2 usable, source sim" in capsys.readouterr().out
    assert main(args) == 2  # the masses are in neither
    assert "sweep.part_masses_kg=None: required" in capsys.readouterr().err
    assert main([*args, "--masses", "x"]) == 2
    assert "--masses: part_masses_kg='x': not a number" in capsys.readouterr().err


def test_bad_plan_file_names_the_entry(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plan = tmp_path / "plan.yaml"
    plan.write_text("sweep:\n  frequencies_hz: 20\n  amplitudes_percent: 40\n  masses: 0.03\n")
    assert "sweep.masses=0.03: unknown field" in _fails(["--plan", str(plan)], capsys)
    plan.write_text("sweep: {frequencies_hz: 20, amplitudes_percent: 40, part_masses_kg: 0.03}\n"
                    "fit: {orders: '1/2', weights: 1}\n")  # fmt: skip
    assert "fit.weights: unknown" in _fails(["--plan", str(plan)], capsys)
    sweep = "sweep: {frequencies_hz: 20, amplitudes_percent: 40, part_masses_kg: 0.03}\n"
    for bad in (".nan", "-0.01", ".inf"):
        plan.write_text(sweep + f"fit: {{min_speed_mps: {bad}}}\n")
        err = _fails(["--plan", str(plan)], capsys)
        assert f"{plan}: fit.min_speed_mps=" in err
        assert "must be >= 0 and finite" in err


def test_bag_source(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "recorded"
    write_sweep_bag(bag)
    out = tmp_path / "out"
    args = ["--source", "bag", str(bag), "--masses", "0.031", "--window", "1.5", "--no-fit"]
    assert main(["identify", *args, "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "bag segments: 4 driven (4 from ground truth)" in printed
    sweep = SweepResult.read_csv(out / "sweep.csv")
    assert [(p.frequency_hz, p.ok) for p in sweep.points] == [
        (20.0, True),
        (21.0, True),
        (22.0, False),
        (23.0, True),
    ]
    assert [round(p.speed_mps, 9) for p in sweep.points if p.ok] == [0.016, 0.012, 0.004]
    err = _fails(["--source", "bag", str(bag), "--masses", "0.03,0.06"], capsys)
    assert "2 part masses (0.03, 0.06 kg) for 1 bag(s)" in err


def test_bag_source_reports_the_bag_problems(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A cut-short bag still gives its points, and the command says what the reader found."""
    bag = tmp_path / "recorded"
    write_sweep_bag(bag)
    mcap = bag / "recorded_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) * 3 // 4])
    args = ["--source", "bag", str(bag), "--masses", "0.031", "--window", "1.5", "--no-fit"]
    assert main(["identify", *args]) == 0
    captured = capsys.readouterr()
    assert "bag segments:" in captured.out
    assert f"feeder identify: {bag}: warning: cut short" in captured.err
    assert f"feeder identify: {bag}: problem: [cut_short] {mcap}" in captured.err


def test_bag_source_with_lost_data_writes_its_results_and_exits_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A split file of a sweep bag lost (listed in metadata.yaml, gone): the points come from
    what could be read, the outputs are written, and the exit status says data was lost (like
    feeder analyze)."""
    import yaml

    bag = tmp_path / "recorded"
    write_sweep_bag(bag)
    meta_path = bag / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    meta["rosbag2_bagfile_information"]["relative_file_paths"].append("recorded_1.mcap")
    meta_path.write_text(yaml.safe_dump(meta))
    out = tmp_path / "out"
    args = ["--source", "bag", str(bag), "--masses", "0.031", "--window", "1.5", "--no-fit"]
    assert main(["identify", *args, "--output", str(out)]) == 1
    captured = capsys.readouterr()
    assert f"feeder identify: {bag}: warning: data lost (" in captured.err
    assert "feeder identify: data lost in 1 bag(s)" in captured.err
    assert "bag segments:" in captured.out
    assert (out / "sweep.csv").read_text().count("\n") > 1  # header and measured points


def test_an_order_the_hold_out_cannot_score_is_left_out_not_the_whole_curve() -> None:
    """5 frequencies: order 0/1 can be scored on held-out pairs, 0/2 needs 6 (runs of 2 held out
    per fold): 0/2 is left out with the reason and the curve is still fitted."""
    from feeder_ros.identification.group_fit import FitSettings, fit_group
    from feeder_ros.identification.sweep import SweepGroup

    f = np.array([19.0, 20.0, 21.0, 22.0, 23.0])
    v = 0.02 / (1.0 + ((f - 20.5) / 1.5) ** 2)
    group = SweepGroup(40.0, 40.0, 0.031, f, v)
    outcome = fit_group(group, FitSettings(orders=((0, 1), (0, 2))))
    assert outcome.error == ""
    assert outcome.best is not None
    assert (outcome.best.zeros, outcome.best.poles) == (0, 1)
    assert outcome.left_out == ["order 0/2 needs 6 frequencies for the hold-out check, 5 usable"]


def test_the_loop_closes_identify_then_command_a_speed_then_it_is_reached(tmp_path: Path) -> None:
    """identify (simulator sweep) -> model file -> the drive interface's target-speed choice
    (the same identified table the node builds) -> the exact simulation at that setting reaches
    the target within the speed monitor's default tolerance (no under/overspeed alarm)."""
    from feeder_ros.drive.limits import DriveLimits
    from feeder_ros.identification.speed_model_file import identified_speed_table, load_speed_model
    from feeder_ros.monitoring.speed_monitor import MonitorConfig
    from feeder_ros.physics.simulation import simulate_many

    model_path = tmp_path / "model.yaml"
    args = ["identify", "--amplitudes", "30,40,50", "--masses", "0.05"]
    assert main([*args, "--model-out", str(model_path)]) == 0
    limits = DriveLimits(min_frequency_hz=10.0, max_frequency_hz=60.0)
    table = identified_speed_table(load_speed_model(model_path), limits, part_mass_kg=0.05)
    plant = load_parameters(default_config_path(), preset="realistic")
    assert plant.part_mass_kg == 0.05
    tolerance = MonitorConfig().speed_tolerance
    for target in (0.006, 0.010, 0.015, 0.020):
        choice = table.choose(target)
        assert choice is not None, target
        point = plant.with_changes(
            drive_frequency_hz=choice.frequency_hz,
            drive_amplitude_n=limits.force_n(choice.amplitude_percent),
            track_length_m=1e3,
        )
        reached = simulate_many([point], 5.0, settle_s=1.0).mean_part_speed_mps[0]
        assert abs(reached / target - 1.0) < tolerance, (target, choice, reached)
