"""``feeder completion bash``: the script completes in a real bash, as the user sources it."""

from __future__ import annotations

import argparse
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from feeder_ros.cli.completion import FUNCTION, bash_script
from feeder_ros.cli.main import SUBCOMMANDS, _load, build_parser, main

FEEDER = str(Path(sys.executable).parent / "feeder")

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")


@pytest.fixture(scope="module")
def script(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("completion") / "feeder.bash"
    path.write_text(bash_script(build_parser()), encoding="utf-8")
    return path


def complete(source: str, line: str, cwd: Path | None = None) -> list[str]:
    """COMPREPLY in a bash that ran ``source``, for ``line`` with the cursor at its end, split
    into words as bash splits it for completion: at blanks (a trailing blank starts an empty
    word) and around ``=`` (``--option=value``: ``--option``, ``=``, ``value``)."""
    words = line.replace("=", " = ").split()
    if line.endswith(" "):
        words.append("")
    program = "\n".join(
        [
            source,
            f"COMP_WORDS=({' '.join(shlex.quote(word) for word in words)})",
            f"COMP_CWORD={len(words) - 1}",
            f"COMP_LINE={shlex.quote(line)}",
            f"COMP_POINT={len(line)}",
            f"{FUNCTION} feeder {shlex.quote(words[-1])} {shlex.quote(words[-2])}",
            'printf "%s\\n" "${COMPREPLY[@]}"',
            # the function is registered for feeder, with file names as the fallback
            "complete -p feeder >&2",
        ]
    )
    done = subprocess.run(
        ["bash", "--norc", "--noprofile", "-c", program],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == f"complete -o default -F {FUNCTION} feeder"
    return [word for word in done.stdout.splitlines() if word]


def test_sourced_from_the_command_as_documented() -> None:
    # the line the help gives: source <(feeder completion bash)
    assert complete(f"source <({shlex.quote(FEEDER)} completion bash)", "feeder re") == [
        "record",
        "reindex",
    ]


def test_the_script_is_printed_by_the_sub_command(
    script: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["completion", "bash"]) == 0
    assert capsys.readouterr().out == script.read_text(encoding="utf-8")


def test_an_unknown_shell_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main(["completion", "tcsh"])
    assert done.value.code == 2
    assert "invalid choice: 'tcsh'" in capsys.readouterr().err


def test_sub_commands(script: Path) -> None:
    assert complete(f"source {script}", "feeder ") == [*SUBCOMMANDS, "--help", "--version"]
    assert complete(f"source {script}", "feeder an") == ["analyze"]
    assert complete(f"source {script}", "feeder --") == ["--help", "--version"]


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("feeder record --c", ["--chunk-size", "--compression"]),
        ("feeder cell --", ["--composed", "--config", "--duration", "--foxglove", "--help",
                            "--list", "--params-out"]),
        ("feeder info --", ["--help", "--json", "--verify"]),
        ("feeder sim --duration 2 --p", ["--parts", "--plot", "--preset", "--progress"]),
        ("feeder identify --source live --no-", ["--no-fit", "--no-lifecycle"]),
    ],
)  # fmt: skip
def test_a_sub_command_s_long_options(script: Path, line: str, expected: list[str]) -> None:
    assert complete(f"source {script}", line) == expected


def test_every_sub_command_s_long_options_are_offered(script: Path) -> None:
    for name in SUBCOMMANDS:
        parser = argparse.ArgumentParser()
        _load(name).add_arguments(parser)
        options = sorted(o for a in parser._actions for o in a.option_strings if o[:2] == "--")
        assert complete(f"source {script}", f"feeder {name} --") == options, name


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("feeder record --compression ", ["zstd", "lz4", "none"]),
        ("feeder record --compression=", ["zstd", "lz4", "none"]),
        ("feeder record --compression=l", ["lz4"]),
        ("feeder identify --source b", ["bag"]),
        ("feeder design --objective m", ["max-speed", "min-force"]),
        ("feeder completion ", ["bash"]),
    ],
)
def test_choices(script: Path, line: str, expected: list[str]) -> None:
    assert complete(f"source {script}", line) == expected


def test_other_arguments_fall_back_to_file_names(script: Path, tmp_path: Path) -> None:
    # no words from the function: bash's default (file names) completes the bag, the output, ...
    assert complete(f"source {script}", "feeder analyze ", cwd=tmp_path) == []
    assert complete(f"source {script}", "feeder record -o ", cwd=tmp_path) == []
