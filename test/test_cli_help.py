"""``feeder`` as a command line: bare ``feeder``, ``--version``, the examples in every ``--help``,
and Ctrl-C while the command loads (in-process; the Ctrl-C of running processes:
test_cli_signals.py)."""

from __future__ import annotations

import argparse
import importlib.metadata
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from feeder_ros.cli import main as cli_main
from feeder_ros.cli.main import SUBCOMMANDS, build_parser, main

REPO = Path(__file__).resolve().parents[1]
FEEDER = str(Path(sys.executable).parent / "feeder")


def _help(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    with pytest.raises(SystemExit) as done:
        main([*argv, "--help"])
    assert done.value.code == 0
    return capsys.readouterr().out


def _examples(text: str) -> list[str]:
    """The command lines of the help's ``examples:`` block (comment lines left out)."""
    block = text.split("\nexamples:\n", 1)[1].split("\n\n", 1)[0]
    return [line.strip() for line in block.splitlines() if not line.strip().startswith("#")]


def test_bare_feeder_prints_the_help_on_stdout_and_exits_0() -> None:
    done = subprocess.run([FEEDER], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert done.stdout.startswith("usage: feeder ")
    for name in SUBCOMMANDS:  # the full help: every command with its summary
        assert re.search(rf"^    {name}\b", done.stdout, re.MULTILINE), name
    assert "examples:" in done.stdout
    asked = subprocess.run([FEEDER, "--help"], capture_output=True, text=True, timeout=120)
    assert done.stdout == asked.stdout


def test_bare_feeder_with_an_unknown_option_is_a_usage_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as done:
        main(["--colour"])
    assert done.value.code == 2
    assert "unrecognized arguments: --colour" in capsys.readouterr().err


def test_version_is_the_installed_distribution_s(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out == f"feeder {importlib.metadata.version('feeder_ros')}\n"


def test_version_not_installed_is_package_xml_s(monkeypatch: pytest.MonkeyPatch) -> None:
    def not_installed(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    xml = (REPO / "package.xml").read_text(encoding="utf-8")
    version = re.search(r"<version>\s*([^<\s]+)\s*</version>", xml)
    assert version is not None
    assert cli_main.version() == version.group(1)


def test_the_version_line_as_a_process() -> None:
    done = subprocess.run([FEEDER, "--version"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert re.fullmatch(r"feeder \d+\.\d+\.\d+\S*\n", done.stdout)


@pytest.mark.parametrize("name", ["", *SUBCOMMANDS])
def test_every_help_has_two_to_four_examples_that_parse(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text = _help(capsys, *([name] if name else []))
    lines = _examples(text)
    if name:
        assert 2 <= sum(f"feeder {name} " in line for line in lines) <= 4, lines
    else:
        assert sum("feeder " in line for line in lines) >= 3, lines
    parser = build_parser()
    for line in lines:
        # each command of the line (``a && b``, ``a | head``, ``a > file``) is one feeder accepts
        for part in re.split(r"\s*(?:&&|\||>)\s*", line):
            words = shlex.split(part.replace("<(", "").rstrip(")"))
            words = words[words.index("feeder") + 1 :] if "feeder" in words else []
            if not words:
                continue
            args = parser.parse_args(words)  # a usage error exits 2: the test fails
            assert isinstance(args, argparse.Namespace)
            assert args.command in SUBCOMMANDS


@pytest.mark.parametrize("name", list(SUBCOMMANDS))
def test_examples_keep_their_layout_in_a_narrow_terminal(
    name: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "50")
    text = _help(capsys, name)
    module = cli_main._load(name)
    epilog = getattr(module, "EPILOG", "")
    block = epilog.split("examples:\n", 1)[1]
    assert block in text  # verbatim, no line re-wrapped to 50 columns
    prose = text.split("\nexamples:\n", 1)[0].split("\n\n")[-1]
    assert all(len(line) <= 50 for line in prose.splitlines()), prose  # prose is wrapped


@pytest.mark.parametrize("name", ["cell", "record"])
def test_cell_and_record_say_ctrl_c_is_their_normal_end(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text = " ".join(_help(capsys, name).split())
    assert "Ctrl-C: the normal way to" in text
    assert "then exit status 0" in text
    assert "exit status 130" in text  # before the work began


def test_ctrl_c_while_the_command_loads_is_exit_130_without_a_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupted() -> argparse.ArgumentParser:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli_main, "build_parser", interrupted)
    assert main(["sim"]) == 130
    assert capsys.readouterr().err == "feeder: interrupted\n"


def test_ctrl_c_before_the_bag_exists_is_exit_130_and_no_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import feeder_ros.recording

    def interrupted(**kwargs: object) -> None:
        raise KeyboardInterrupt  # as if Ctrl-C came while the recorder starts

    monkeypatch.setattr(feeder_ros.recording, "RecordingOptions", interrupted)
    assert main(["record", "-o", str(tmp_path / "bag")]) == 130
    assert capsys.readouterr().err == "feeder: interrupted\n"
    assert not (tmp_path / "bag").exists()


def test_the_help_loads_no_numerical_library_beyond_numpy() -> None:
    """``feeder --help`` (and every command's options) come from the sub-command modules alone:
    the optimizer, the sweep fit, the figures and the physics core (scipy, matplotlib, numba)
    load when a command runs, so the help answers at once (0.3 s against 1.4 s when it
    imported them all)."""
    probe = (
        "import sys\n"
        "from feeder_ros.cli.main import build_parser\n"
        "build_parser().format_help()\n"
        "print(' '.join(sorted(m for m in ('scipy', 'matplotlib', 'numba', 'rclpy')"
        " if m in sys.modules)))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=REPO
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == ""
