"""Output paths are checked before any work: a bad one is refused at once, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

from feeder_ros.cli.main import CommandError, main
from feeder_ros.cli.outputs import (
    MANIFEST_NAME,
    check_output_dir,
    check_output_file,
    replace_earlier_outputs,
)


def test_output_file_rules(tmp_path: Path) -> None:
    check_output_file(None, "--output")  # not given: nothing to check
    check_output_file(tmp_path / "new.csv", "--output")
    (tmp_path / "old.csv").write_text("x")
    check_output_file(tmp_path / "old.csv", "--output")  # replaced when written
    with pytest.raises(CommandError, match=r"--output .*: is a directory"):
        check_output_file(tmp_path, "--output")
    with pytest.raises(CommandError, match=r"--events .*missing/x.csv: directory .*missing does"):
        check_output_file(tmp_path / "missing" / "x.csv", "--events")
    with pytest.raises(CommandError, match=r"--output '\.': not a file name"):
        check_output_file(Path(""), "--output")


def test_output_dir_rules(tmp_path: Path) -> None:
    check_output_dir(None, "--plot")
    check_output_dir(tmp_path / "a" / "b", "--plot")  # created when written
    assert not (tmp_path / "a").exists()  # the check itself leaves nothing behind
    assert [p.name for p in tmp_path.iterdir()] == []
    (tmp_path / "file").write_text("x")
    with pytest.raises(CommandError, match=r"--plot .*file: exists and is not a directory"):
        check_output_dir(tmp_path / "file", "--plot")
    with pytest.raises(CommandError, match=r"--output .*file/sub: .*file is not a directory"):
        check_output_dir(tmp_path / "file" / "sub", "--output")
    (tmp_path / "used" / MANIFEST_NAME).mkdir(parents=True)  # the record's name taken
    with pytest.raises(CommandError, match=rf"--plot .*used: .*{MANIFEST_NAME} is not a file"):
        check_output_dir(tmp_path / "used", "--plot")
    (tmp_path / "fine").mkdir()
    (tmp_path / "fine" / MANIFEST_NAME).write_text("a.png\n")
    check_output_dir(tmp_path / "fine", "--plot")  # a record: the run replaces it


def _refused(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(args) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # refused before any work: nothing simulated or printed
    return captured.err


def test_sim_refuses_a_bad_plot_dir_before_writing_its_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "taken").write_text("x")
    csv = tmp_path / "samples.csv"
    err = _refused(
        ["sim", "--duration", "0.1", "--output", str(csv), "--plot", str(tmp_path / "taken")],
        capsys,
    )
    assert f"--plot {tmp_path / 'taken'}: exists and is not a directory" in err
    assert not csv.exists()
    (tmp_path / "plots" / MANIFEST_NAME).mkdir(parents=True)
    err = _refused(
        ["sim", "--duration", "0.1", "--output", str(csv), "--plot", str(tmp_path / "plots")],
        capsys,
    )
    assert f"{tmp_path / 'plots' / MANIFEST_NAME} is not a file" in err
    assert not csv.exists()
    assert [p.name for p in (tmp_path / "plots").iterdir()] == [MANIFEST_NAME]


def test_design_refuses_its_output_before_the_search(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "taken").write_text("x")
    err = _refused(["design", "--output", str(tmp_path / "taken")], capsys)
    assert f"--output {tmp_path / 'taken'}: exists and is not a directory" in err


def test_identify_refuses_a_model_file_that_is_a_directory_before_the_sweep(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    err = _refused(
        ["identify", "--source", "sim", "--frequencies", "20", "--amplitudes", "40",
         "--masses", "0.05", "--output", str(out), "--model-out", str(tmp_path)],
        capsys,
    )  # fmt: skip
    assert f"--model-out {tmp_path}: is a directory" in err
    assert not out.exists()


def test_analyze_refuses_an_output_under_a_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "taken").write_text("x")
    err = _refused(
        ["analyze", str(tmp_path / "no_bag"), "--output", str(tmp_path / "taken" / "out")], capsys
    )
    assert "taken is not a directory" in err


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["design", "--map-points", "1"], "argument --map-points: '1' must be >= 2"),
        (["design", "--seed", "-1"], "argument --seed: '-1' must be >= 0"),
    ],
)
def test_design_options_are_checked_by_the_parser(
    args: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        main(args)
    assert stop.value.code == 2
    assert needle in capsys.readouterr().err


def test_sim_refuses_a_run_whose_samples_exceed_the_memory(
    capsys: pytest.CaptureFixture[str],
) -> None:
    err = _refused(["sim", "--duration", "100000", "--rate", "100000"], capsys)
    assert "is 10,000,000,001 samples" in err
    assert "more than this machine's memory" in err


def test_an_output_directory_written_again_keeps_only_this_runs_files(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    for name in ("a.csv", "b.png", "user.txt"):
        (out / name).write_text(name)
    assert replace_earlier_outputs(out, [out / "a.csv", out / "b.png"]) == []
    assert (out / MANIFEST_NAME).read_text() == "a.csv\nb.png\n"
    # the next run writes a.csv and c.json: b.png is the earlier run's and goes
    (out / "c.json").write_text("{}")
    assert replace_earlier_outputs(out, [out / "a.csv", out / "c.json"]) == ["b.png"]
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "a.csv", "c.json", "user.txt"]
    assert (out / MANIFEST_NAME).read_text() == "a.csv\nc.json\n"
    # paths outside the directory are not recorded
    assert replace_earlier_outputs(out, [out / "a.csv", tmp_path / "elsewhere.csv"]) == ["c.json"]
    assert (out / MANIFEST_NAME).read_text() == "a.csv\n"


def test_a_record_cannot_reach_outside_the_directory(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "sub").mkdir(parents=True)
    outside = tmp_path / "precious.txt"
    outside.write_text("keep")
    (out / "link.png").symlink_to(outside)
    (out / "sub" / "x.csv").write_text("keep")
    (out / MANIFEST_NAME).write_text(
        f"../precious.txt\n{outside}\nsub\nsub/x.csv\nlink.png\n..\n.\n\nmissing.csv\n"
    )
    assert replace_earlier_outputs(out, []) == []
    assert outside.read_text() == "keep"
    assert (out / "link.png").is_symlink()
    assert (out / "sub" / "x.csv").read_text() == "keep"
    assert (out / MANIFEST_NAME).read_text() == ""


def test_a_file_that_cannot_be_removed_stays_recorded(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path
    (out / "old.png").write_text("x")
    (out / MANIFEST_NAME).write_text("old.png\n")
    real_unlink = Path.unlink

    def refuse(self: Path, missing_ok: bool = False) -> None:
        if self.name == "old.png":
            raise PermissionError(13, "Permission denied", str(self))
        real_unlink(self, missing_ok)

    monkeypatch.setattr(Path, "unlink", refuse)
    assert replace_earlier_outputs(out, [out / "new.png"]) == []
    assert (out / MANIFEST_NAME).read_text() == "new.png\nold.png\n"
    monkeypatch.undo()
    assert replace_earlier_outputs(out, [out / "new.png"]) == ["old.png"]
    assert not (out / "old.png").exists()
