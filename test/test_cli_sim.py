"""``feeder sim`` in-process: CSV layout, exact sample times, values, refusals, atomic output."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from feeder_ros.cli.main import main
from feeder_ros.cli.sim import default_config_path, load_parameters
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import EventKind, PartSpec, simulate


def _read(path: Path) -> tuple[list[str], np.ndarray]:
    with path.open(newline="") as stream:
        rows = list(csv.reader(stream))
    return rows[0], np.array(rows[1:], dtype=np.float64)


def test_default_config_is_the_case_study() -> None:
    path = default_config_path()
    assert path.name == "platform_simulator.yaml"
    assert load_parameters(path) == FeederParameters()


def test_csv_header_sample_times_and_values(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.csv"
    code = main(
        ["sim", "--set", "drive_amplitude_n=40", "--duration", "0.25", "--rate", "300",
         "--parts", "2", "--output", str(out)]
    )  # fmt: skip
    assert code == 0
    header, data = _read(out)
    assert header == [
        "t_s", "carrier_x_m", "carrier_v_mps", "carrier_a_mps2", "branch",
        "part0_x_m", "part0_v_mps", "part0_phase", "part1_x_m", "part1_v_mps", "part1_phase",
    ]  # fmt: skip
    # samples at exact multiples of 1/rate: 0, 1/300, ..., 75/300
    np.testing.assert_array_equal(data[:, 0], np.arange(76) / 300.0)
    params = FeederParameters(drive_amplitude_n=40.0)
    expected = simulate(
        params, 0.25, 300.0, parts=(PartSpec(position_m=0.0), PartSpec(position_m=0.125))
    )
    np.testing.assert_array_equal(data[:, 1], expected.carrier_x_m)
    np.testing.assert_array_equal(data[:, 2], expected.carrier_v_mps)
    np.testing.assert_array_equal(data[:, 3], expected.carrier_a_mps2)
    np.testing.assert_array_equal(data[:, 4], expected.branch)
    np.testing.assert_array_equal(data[:, 5::3], expected.part_x_m)
    np.testing.assert_array_equal(data[:, 6::3], expected.part_v_mps)
    np.testing.assert_array_equal(data[:, 7::3], expected.part_phase)
    summary = capsys.readouterr().out
    assert "mean part speed" in summary
    assert "slip fraction" in summary
    assert f"events: {expected.event_t_s.size}" in summary
    assert "real-time factor" in summary


def test_events_file(tmp_path: Path) -> None:
    events = tmp_path / "events.csv"
    assert main(["sim", "--set", "drive_amplitude_n=40", "--duration", "0.1",
                 "--events", str(events)]) == 0  # fmt: skip
    with events.open(newline="") as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ["t_s", "kind", "part"]
    expected = simulate(FeederParameters(drive_amplitude_n=40.0), 0.1, 1000.0)
    assert [float(r[0]) for r in rows[1:]] == expected.event_t_s.tolist()
    assert [r[1] for r in rows[1:]] == [EventKind(int(k)).name for k in expected.event_kind]
    assert [int(r[2]) for r in rows[1:]] == expected.event_part.tolist()
    slip_starts = [float(r[0]) for r in rows[1:] if r[1] == "SLIP_START"]
    assert slip_starts[0] == pytest.approx(0.003, abs=5e-4)


def test_progress_bar_runs_in_chunks_with_the_same_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plain, chunked = tmp_path / "plain.csv", tmp_path / "chunked.csv"
    args = ["sim", "--set", "drive_amplitude_n=40", "--duration", "0.5", "--rate", "1000"]
    assert main([*args, "--output", str(plain)]) == 0
    assert "simulating" not in capsys.readouterr().err  # not a terminal: no bar
    assert main([*args, "--progress", "--output", str(chunked)]) == 0
    assert "simulating 100%|" in capsys.readouterr().err
    # chunks restart the closed forms from the saved state: equal up to round-off
    a, b = _read(plain)[1], _read(chunked)[1]
    np.testing.assert_array_equal(a[:, 0], b[:, 0])
    np.testing.assert_array_equal(a[:, 4], b[:, 4])
    scale = np.abs(a).max(axis=0)
    assert np.all(np.abs(a - b) <= 1e-9 * scale)


def test_plot_directory(tmp_path: Path) -> None:
    figures = tmp_path / "figs"
    assert main(["sim", "--duration", "0.1", "--plot", str(figures)]) == 0
    names = sorted(p.name for p in figures.iterdir())
    pngs = [
        "carrier_displacement.png",
        "first_40ms.png",
        "parts_over_run.png",
        "phase_portrait.png",
    ]
    assert names == [".feeder-outputs", *pngs]
    assert (figures / ".feeder-outputs").read_text().splitlines() == pngs


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("part_mass_kg=-1", "part_mass_kg=-1"),
        ("forward_length_m=0", "forward_length_m=0"),
        ("static_friction=nan", "static_friction=nan"),
        ("kinetic_friction=0.3", "kinetic_friction=0.3"),
        ("no_such_thing=1", "unknown parameter 'no_such_thing'"),
        ("stiffness_switch=sideways", "stiffness_switch='sideways'"),
        ("drive_amplitude_n", "expected name=value"),
    ],
)
def test_bad_parameters_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], setting: str, message: str
) -> None:
    out = tmp_path / "never.csv"
    assert main(["sim", "--set", setting, "--output", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("feeder sim: error: ")
    assert message in err
    assert err.count("\n") == 1
    assert not out.exists()


def test_bad_config_files_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--config", str(tmp_path / "missing.yaml")]) == 2
    assert "missing.yaml" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("platform_simulator:\n  ros__parameters:\n    carrier_mass_kg: -3.0\n")
    assert main(["sim", "--config", str(bad)]) == 2
    assert "carrier_mass_kg=-3.0" in capsys.readouterr().err
    bad.write_text("other_node:\n  ros__parameters: {}\n")
    assert main(["sim", "--config", str(bad)]) == 2
    assert "ros__parameters" in capsys.readouterr().err
    bad.write_bytes(b"platform_simulator:\n\x8d\xff")
    assert main(["sim", "--config", str(bad)]) == 2
    assert f"{bad}: not UTF-8 text (invalid start byte at byte 20)" in capsys.readouterr().err
    assert main(["sim", "--set", "mass_coefficient=2"]) == 2  # a pure number: no unit named
    assert "error: mass_coefficient=2.0 must be <= 1\n" in capsys.readouterr().err
    good = tmp_path / "good.yaml"
    good.write_text("platform_simulator:\n  ros__parameters:\n    drive_amplitude_n: 40.0\n")
    assert load_parameters(good, ["damping_ns_per_m=30"]) == FeederParameters(
        drive_amplitude_n=40.0, damping_ns_per_m=30.0
    )


def test_a_run_the_solver_cannot_continue_fails_without_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # driven exactly at the undamped forward branch's natural frequency: no closed form
    resonant = FeederParameters().forward_natural_frequency_hz
    out = tmp_path / "never.csv"
    args = ["sim", "--set", f"drive_frequency_hz={resonant!r}", "--duration", "0.1"]
    assert main([*args, "--output", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("feeder sim: simulation failed: sharp solver stopped at t=0.0 s: ")
    assert "exact resonance of an undamped branch" in err
    assert not out.exists()


def test_run_as_a_module_its_errors_are_still_messages(tmp_path: Path) -> None:
    missing = tmp_path / "missing.yaml"
    done = subprocess.run(
        [sys.executable, "-m", "feeder_ros.cli.main", "sim", "--config", str(missing)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr == f"feeder sim: error: --config {missing}: no such file\n"


def test_a_failed_figure_leaves_no_partial_png(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def half_written(figure: Figure, path: Path, **kwargs: object) -> None:
        Path(path).write_bytes(b"\x89PNG half")
        raise OSError("disk full")

    monkeypatch.setattr(Figure, "savefig", half_written)
    figures = tmp_path / "figs"
    assert main(["sim", "--duration", "0.1", "--plot", str(figures)]) == 2
    assert capsys.readouterr().err == "feeder sim: error: disk full\n"
    assert list(figures.iterdir()) == []


def test_bad_options_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    for option in (["--duration", "-1"], ["--rate", "0"], ["--parts", "-2"], ["--rate", "inf"]):
        with pytest.raises(SystemExit) as exit_info:
            main(["sim", *option])
        assert exit_info.value.code == 2
        assert option[1] in capsys.readouterr().err


def test_an_unknown_option_is_named_by_the_sub_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["sim", "--duration", "1", "--bogus"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "usage: feeder sim" in err
    assert "feeder sim: error: unrecognized arguments: --bogus" in err


def test_the_default_run_says_the_part_never_slips_and_how_to_see_slip(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["sim"]) == 0
    out = capsys.readouterr().out
    assert "no part ever slipped: the carrier's peak acceleration" in out
    assert "To see slip, drive harder (about --set drive_amplitude_n=" in out


def test_a_likely_unit_mistake_is_warned_and_the_run_still_made(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["sim", "--duration", "0.2", "--set", "drive_frequency_hz=600"]) == 0
    captured = capsys.readouterr()
    assert (
        "feeder sim: warning: drive_frequency_hz=600 is 18x the carrier's highest" in captured.err
    )
    assert (
        "feeder sim: warning: drive_frequency_hz=600 is above half the output rate" in captured.err
    )
    assert "f_d = 600 Hz" in captured.out
