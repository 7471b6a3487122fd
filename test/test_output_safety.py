"""Outputs are safe: what an output path names is written as the user meant, or refused at once.

A symbolic link is followed and kept, a FIFO or a device is written in place (never replaced by a
regular file), ``-`` and the names of standard output stream ``feeder sim``'s CSV there, and
nothing is written into a bag directory.

Standard output is reached in these tests through ``/dev/fd/1``, a link to ``/dev/stdout`` and
``-``, never by writing the name ``/dev/stdout`` itself: a writer that replaces its target (the bug
these tests guard against) would replace the machine's ``/dev/stdout`` when run as root.
"""

from __future__ import annotations

import errno
import os
import select
import socket
import stat
import subprocess
import sys
import tempfile
import tty
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from bag.test_analysis import write_feeder_bag
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

import feeder_ros.cli.outputs as outputs
from feeder_ros.atomic_files import atomic_bytes, atomic_text
from feeder_ros.bag import BagWriter
from feeder_ros.cli.main import CommandError, main

SIM = ["sim", "--duration", "0.05", "--rate", "1000"]  # 51 samples: about 4 kB of CSV
FEEDER = [sys.executable, "-m", "feeder_ros.cli.main"]


# ----------------------------------------------------------------------------------- helpers


@pytest.fixture(scope="module")
def reference_csv(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The samples CSV of :data:`SIM`, written to a regular file."""
    path = tmp_path_factory.mktemp("reference") / "samples.csv"
    assert main([*SIM, "--output", str(path)]) == 0
    text = path.read_text(encoding="utf-8")
    assert text.startswith("t_s,carrier_x_m,")
    assert text.count("\n") == 52  # header + 51 rows
    return text


def _fifo_reader(path: Path) -> int:
    """A FIFO at ``path`` with a reader already open (non-blocking), so that a writer's open
    does not wait; what it writes stays in the pipe's buffer (64 KiB) until read."""
    os.mkfifo(path)
    return os.open(path, os.O_RDONLY | os.O_NONBLOCK)


def _drain(fd: int) -> bytes:
    chunks = []
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            break
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks)


@pytest.fixture
def terminal() -> Iterator[tuple[int, Path]]:
    """A pseudo-terminal in raw mode: (master fd, the slave's device path, a char device)."""
    master, slave = os.openpty()
    tty.setraw(slave)  # no echo, no newline translation: what is written is what is read
    try:
        yield master, Path(os.ttyname(slave))
    finally:
        os.close(slave)
        os.close(master)


def _read_terminal(master: int, size: int) -> bytes:
    data = b""
    while len(data) < size:
        ready, _, _ = select.select([master], [], [], 5.0)
        if not ready:
            break
        data += os.read(master, 4096)
    return data


def _unix_socket(path: Path) -> socket.socket:
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    return server


def _make_bag(path: Path) -> dict[str, bytes]:
    """A small real bag (metadata.yaml and one .mcap file); returns its files' contents."""
    with BagWriter(path) as writer:
        writer.add_topic("/x", "std_msgs/msg/Float64")
        for i in range(10):
            writer.write("/x", bytes(serialize_message(Float64(data=float(i)))), 10**18 + i)
    return _contents(path)


def _contents(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def _refused(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(args) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    return captured.err


# ------------------------------------------------------------------ the atomic writers: links


def test_a_link_is_followed_and_its_target_replaced_beside_itself(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "data").mkdir()
    (tmp_path / "links").mkdir()
    target = tmp_path / "data" / "samples.csv"
    target.write_text("old\n")
    link = tmp_path / "links" / "samples.csv"
    link.symlink_to("../data/samples.csv")
    chained = tmp_path / "links" / "again.csv"
    chained.symlink_to("samples.csv")  # a link to the link
    temporaries: list[Path] = []
    real_mkstemp = tempfile.mkstemp

    def spy(*args: Any, **kwargs: Any) -> tuple[int, str]:
        fd, name = real_mkstemp(*args, **kwargs)
        temporaries.append(Path(name))
        return fd, name

    monkeypatch.setattr(tempfile, "mkstemp", spy)  # the module atomic_files uses
    with atomic_text(link) as stream:
        stream.write("new\n")
    with atomic_text(chained) as stream:
        stream.write("newer\n")
    assert target.read_text() == "newer\n"
    assert os.readlink(link) == "../data/samples.csv"
    assert os.readlink(chained) == "samples.csv"
    assert [t.parent for t in temporaries] == [target.parent, target.parent]
    assert sorted(p.name for p in (tmp_path / "links").iterdir()) == ["again.csv", "samples.csv"]
    assert [p.name for p in (tmp_path / "data").iterdir()] == ["samples.csv"]


def test_a_dangling_link_writes_its_target(tmp_path: Path) -> None:
    link = tmp_path / "model.yaml"
    link.symlink_to(tmp_path / "models" / "m1.yaml")
    (tmp_path / "models").mkdir()
    atomic_bytes(link, b"a: 1\n")
    assert link.is_symlink()
    assert (tmp_path / "models" / "m1.yaml").read_bytes() == b"a: 1\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.yaml", "models"]


def test_a_dangling_link_into_a_missing_directory_is_refused_naming_it(tmp_path: Path) -> None:
    link = tmp_path / "out.csv"
    link.symlink_to(tmp_path / "gone" / "out.csv")
    entered = False
    with pytest.raises(FileNotFoundError) as caught, atomic_text(link):
        entered = True
    assert not entered  # refused before anything was written
    assert caught.value.filename == str(link)
    assert f"symbolic link to {tmp_path / 'gone' / 'out.csv'}" in str(caught.value)
    assert f"whose directory {tmp_path / 'gone'}, does not exist" in str(caught.value)
    assert link.is_symlink()
    assert not (tmp_path / "gone").exists()


def test_a_loop_of_links_is_refused(tmp_path: Path) -> None:
    (tmp_path / "a").symlink_to("b")
    (tmp_path / "b").symlink_to("a")
    with pytest.raises(OSError, match="a loop of symbolic links") as caught:
        atomic_bytes(tmp_path / "a", b"x")
    assert caught.value.errno == errno.ELOOP
    assert os.readlink(tmp_path / "a") == "b"
    assert os.readlink(tmp_path / "b") == "a"


# --------------------------------------------------- the atomic writers: streams, sockets, dirs


def test_a_fifo_is_written_in_place(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    reader = _fifo_reader(fifo)
    try:
        with atomic_text(fifo, durable=True) as stream:  # a pipe cannot be fsynced: not tried
            stream.write("t_s,x_m\n0.0,1.5\n")
        atomic_bytes(fifo, b"0.001,1.25\n")
        assert _drain(reader) == b"t_s,x_m\n0.0,1.5\n0.001,1.25\n"
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["pipe"]


def test_a_terminal_is_written_in_place_also_through_a_link(
    tmp_path: Path, terminal: tuple[int, Path]
) -> None:
    master, device = terminal
    link = tmp_path / "tty"
    link.symlink_to(device)
    with atomic_text(link) as stream:
        stream.write("through the link\n")
    with atomic_text(device) as stream:
        stream.write("direct\n")
    expected = b"through the link\ndirect\n"
    assert _read_terminal(master, len(expected)) == expected
    assert os.readlink(link) == str(device)
    assert stat.S_ISCHR(os.stat(device).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["tty"]


def test_dev_null_behind_a_link_stays_a_device(tmp_path: Path) -> None:
    link = tmp_path / "discard.csv"
    link.symlink_to("/dev/null")
    with atomic_text(link, durable=True) as stream:
        stream.write("gone\n")
    assert os.readlink(link) == "/dev/null"
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["discard.csv"]


def test_a_socket_is_refused_and_kept(tmp_path: Path) -> None:
    path = tmp_path / "s"
    with _unix_socket(path):
        entered = False
        with pytest.raises(OSError, match="is a socket") as caught, atomic_text(path):
            entered = True
        assert not entered
        assert caught.value.filename == str(path)
        assert stat.S_ISSOCK(os.lstat(path).st_mode)


def test_a_directory_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    entered = False
    with pytest.raises(IsADirectoryError, match="is a directory"), atomic_text(tmp_path):
        entered = True
    assert not entered
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------- the output checks


def test_the_names_of_standard_output_and_error(tmp_path: Path) -> None:
    for name in ("-", "/dev/stdout", "/dev/fd/1", "/proc/self/fd/1"):
        assert outputs.standard_stream(Path(name)) is sys.stdout, name
    for name in ("/dev/stderr", "/dev/fd/2", "/proc/self/fd/2"):
        assert outputs.standard_stream(Path(name)) is sys.stderr, name
    assert outputs.standard_stream(tmp_path / "x.csv") is None
    (tmp_path / "x.csv").write_text("")
    assert outputs.standard_stream(tmp_path / "x.csv") is None
    named_dash = outputs.output_path("./-")  # a file named '-', said so
    assert named_dash == Path.cwd() / "-"
    assert outputs.standard_stream(named_dash) is None
    assert outputs.output_path("-") == Path("-")


def test_stream_outputs_and_outputs_read_by_name(
    tmp_path: Path, terminal: tuple[int, Path]
) -> None:
    _, device = terminal
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    for path in (Path("-"), fifo, device):
        outputs.check_output_file(path, "--output")  # a stream output: written there
    reason = "the drive interface loads the speed model from a file (speed_model_file)"
    for path, kind in (
        (Path("-"), "standard output"),
        (Path("/dev/fd/2"), "standard error"),
        (fifo, "a FIFO"),
        (device, "a character device"),
    ):
        with pytest.raises(CommandError) as caught:
            outputs.check_output_file(path, "--model-out", by_name=reason)
        assert str(caught.value) == f"--model-out {path}: is {kind}, not a file: {reason}"
    with _unix_socket(tmp_path / "s"), pytest.raises(CommandError) as caught:
        outputs.check_output_file(tmp_path / "s", "--events")
    assert str(caught.value) == (
        f"--events {tmp_path / 's'}: is a socket: only a regular file, a FIFO or a character"
        " device can be written"
    )
    dangling = tmp_path / "link.csv"
    dangling.symlink_to(tmp_path / "nowhere" / "x.csv")
    with pytest.raises(CommandError, match=r"symbolic link to .*nowhere/x\.csv, whose directory"):
        outputs.check_output_file(dangling, "--output")


def test_a_directory_output_cannot_be_standard_output(tmp_path: Path) -> None:
    with pytest.raises(CommandError) as caught:
        outputs.check_output_dir(Path("-"), "--plot", holds="figures (PNG files)")
    assert str(caught.value) == (
        "--plot -: standard output cannot take a directory of figures (PNG files); give a directory"
    )
    dangling = tmp_path / "plots"
    dangling.symlink_to(tmp_path / "missing")
    with pytest.raises(CommandError, match=r"plots: symbolic link to .*missing, which does not"):
        outputs.check_output_dir(dangling, "--plot")
    assert list(tmp_path.iterdir()) == [dangling]


def test_nothing_is_written_into_a_bag_directory(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    before = _make_bag(bag)
    assert sorted(before) == ["bag_0.mcap", "metadata.yaml"]
    loose = tmp_path / "recordings"
    loose.mkdir()
    (loose / "run.mcap").write_bytes(b"")  # read as a bag without metadata.yaml
    (tmp_path / "plain").mkdir()
    assert outputs.is_bag_directory(bag)
    assert outputs.is_bag_directory(loose)
    assert not outputs.is_bag_directory(tmp_path / "plain")
    assert not outputs.is_bag_directory(bag / "metadata.yaml")

    def refusal(call: object, *args: object) -> str:
        with pytest.raises(CommandError) as caught:
            call(*args)  # type: ignore[operator]
        return str(caught.value)

    into = ": nothing is written into a bag; give a path outside it"
    assert refusal(outputs.check_output_file, bag / "x.csv", "--output") == (
        f"--output {bag / 'x.csv'}: {bag} is a bag directory (metadata.yaml or .mcap files){into}"
    )
    link = tmp_path / "plain" / "x.csv"
    link.symlink_to(bag / "x.csv")  # a link into the bag: its target is what would be written
    assert refusal(outputs.check_output_file, link, "--output").endswith(into)
    assert refusal(outputs.check_output_file, loose / "x.csv", "--events").endswith(into)
    assert refusal(outputs.check_output_dir, bag, "--output").startswith(f"--output {bag}: {bag}")
    outputs.check_output_dir(bag / "report", "--plot")  # a subdirectory is not the bag
    outputs.check_output_dir(tmp_path / "plain" / "report", "--plot")  # next to it is fine
    outputs.check_output_file(tmp_path / "plain" / "y.csv", "--output")
    assert _contents(bag) == before


def test_an_output_is_never_an_input_bag(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _make_bag(bag)
    fresh = tmp_path / "fresh"  # not a bag yet: only being an input makes it one here
    fresh.mkdir()
    for output, inputs, said in (
        (bag, [bag], f"--output {bag}: is the input bag {bag}"),
        (bag, [bag / "metadata.yaml"], f"is the input bag {bag / 'metadata.yaml'}"),
        (bag / "bag_0.mcap", [bag / "bag_0.mcap"], "is the input bag"),
        (fresh, [tmp_path / "x" / ".." / "fresh"], "is the input bag"),
        (fresh / "out", [fresh], f"--output {fresh / 'out'}: lies inside the input bag {fresh}"),
    ):
        with pytest.raises(CommandError) as caught:
            outputs.check_apart_from_inputs(output, "--output", inputs)
        assert said in str(caught.value)
    outputs.check_apart_from_inputs(tmp_path / "out", "--output", [bag, fresh])


# ------------------------------------------------------------------ the commands: feeder sim


def test_sim_csv_to_standard_output(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    reference_csv: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main([*SIM, "--output", "-", "--events", "events.csv"]) == 0
    captured = capsys.readouterr()
    assert captured.out == reference_csv  # the CSV alone: the summary went to stderr
    assert "simulated 0.05 s" in captured.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["events.csv"]  # no file named '-'
    assert (tmp_path / "events.csv").read_text().startswith("t_s,kind,part\n")


def test_sim_refuses_two_outputs_on_one_stream_and_figures_on_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    err = _refused([*SIM, "--output", "-", "--events", "/dev/fd/1"], capsys)
    assert "--output - and --events /dev/fd/1 both write to standard output" in err
    err = _refused([*SIM, "--output", "/dev/fd/2", "--events", "/dev/stderr"], capsys)
    assert "--output /dev/fd/2 and --events /dev/stderr both write to standard error" in err
    err = _refused([*SIM, "--plot", "-"], capsys)
    assert "--plot -: standard output cannot take a directory of figures (PNG files)" in err
    assert list(tmp_path.iterdir()) == []


def test_sim_writes_through_a_link_and_into_a_fifo(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], reference_csv: str
) -> None:
    target = tmp_path / "runs" / "today.csv"
    target.parent.mkdir()
    target.write_text("yesterday\n")
    link = tmp_path / "latest.csv"
    link.symlink_to(target)
    fifo = tmp_path / "events.pipe"
    reader = _fifo_reader(fifo)
    try:
        assert main([*SIM, "--output", str(link), "--events", str(fifo)]) == 0
        events = _drain(reader).decode()
    finally:
        os.close(reader)
    assert "simulated 0.05 s" in capsys.readouterr().out
    assert os.readlink(link) == str(target)
    assert target.read_text() == reference_csv
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert events.startswith("t_s,kind,part\n")
    assert events.count("\n") > 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["events.pipe", "latest.csv", "runs"]


def test_sim_refuses_a_socket(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with _unix_socket(tmp_path / "s"):
        err = _refused([*SIM, "--output", str(tmp_path / "s")], capsys)
        assert stat.S_ISSOCK(os.lstat(tmp_path / "s").st_mode)
    assert f"--output {tmp_path / 's'}: is a socket" in err


def test_sim_streams_into_the_pipe_of_its_standard_output_and_error(
    tmp_path: Path, reference_csv: str
) -> None:
    """In a subprocess whose stdout and stderr are pipes: the CSV arrives on the pipe, whole."""
    link = tmp_path / "out.csv"
    link.symlink_to("/dev/stdout")
    runs = {
        name: subprocess.Popen(
            [*FEEDER, *SIM, "--output", name],
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name in ("-", "/dev/fd/1", str(link), "/dev/fd/2")
    }
    results = {name: run.communicate(timeout=240) for name, run in runs.items()}
    for name, run in runs.items():
        out, err = results[name]
        assert run.returncode == 0, (name, err)
        if name == "/dev/fd/2":
            assert reference_csv in err  # the CSV on stderr, the summary on stdout
            assert "simulated 0.05 s" in out
        else:
            assert out == reference_csv, name
            assert "simulated 0.05 s" in err
    assert os.readlink(link) == "/dev/stdout"  # the link is kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]  # no file named '-'


# ------------------------------------------------------------------ the commands: the others


def test_analyze_refuses_to_write_into_its_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    write_feeder_bag(bag)  # a bag analyze reads whole: refused all the same, nothing written
    before = _contents(bag)
    err = _refused(["analyze", str(bag), "--output", str(bag)], capsys)
    assert f"--output {bag}: is the input bag {bag}" in err
    err = _refused(["analyze", str(bag), "--output", str(bag / "report")], capsys)
    assert f"--output {bag / 'report'}: lies inside the input bag {bag}" in err
    other = tmp_path / "other"
    _make_bag(other)
    err = _refused(["analyze", str(bag), "--output", str(other)], capsys)
    assert f"--output {other}: {other} is a bag directory" in err
    err = _refused(["analyze", str(bag), "--output", "-"], capsys)
    assert "--output -: standard output cannot take a directory of report files" in err
    assert _contents(bag) == before


def test_identify_refuses_a_model_on_standard_output_or_in_a_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    bag = tmp_path / "bag"
    before = _make_bag(bag)
    plan = ["identify", "--frequencies", "20", "--amplitudes", "40", "--masses", "0.05"]
    err = _refused([*plan, "--model-out", "-"], capsys)
    assert (
        "--model-out -: is standard output, not a file: the drive interface loads the speed "
        "model from a file (speed_model_file)"
    ) in err
    err = _refused([*plan, "--model-out", str(bag / "model.yaml")], capsys)
    assert f"{bag} is a bag directory" in err
    err = _refused(
        ["identify", "--source", "bag", str(bag), "--masses", "0.05", "--output", str(bag)], capsys
    )
    assert f"--output {bag}: is the input bag {bag}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]
    assert _contents(bag) == before


def test_cell_refuses_its_parameter_file_on_standard_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    err = _refused(["cell", "--list", "--params-out", "-"], capsys)
    assert "--params-out -: is standard output, not a file: the printed commands read" in err
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    err = _refused(["cell", "--list", "--params-out", str(fifo)], capsys)
    assert f"--params-out {fifo}: is a FIFO, not a file" in err
    assert [p.name for p in tmp_path.iterdir()] == ["pipe"]


def test_record_refuses_standard_output_and_a_bag_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    bag = tmp_path / "bag"
    before = _make_bag(bag)
    for output, said in (
        ("-", "--output -: standard output cannot take a directory of bag files"),
        (str(bag), f"--output {bag}: {bag} is a bag directory"),
    ):
        err = _refused(["record", "--duration", "1", "-o", output], capsys)
        assert said in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]
    assert _contents(bag) == before


def test_design_refuses_a_bag_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "bag"
    before = _make_bag(bag)
    err = _refused(["design", "--output", str(bag)], capsys)
    assert f"--output {bag}: {bag} is a bag directory" in err
    assert _contents(bag) == before
