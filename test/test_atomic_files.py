"""Atomic writers: a file appears complete or not at all (feeder_ros.atomic_files)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from feeder_ros.atomic_files import atomic_bytes, atomic_path, atomic_text
from feeder_ros.figures import save_figure


def _usual_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def test_outputs_are_never_half_written(tmp_path: Path) -> None:
    target = tmp_path / "out.csv"
    target.write_text("old\n")

    def interrupted_write() -> None:
        with atomic_text(target) as stream:
            stream.write("partial")
            raise RuntimeError("simulated failure while writing")

    with pytest.raises(RuntimeError, match="simulated failure"):
        interrupted_write()
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]
    with atomic_text(target) as stream:
        stream.write("new\n")
    assert target.read_text() == "new\n"
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600


def test_a_failed_writer_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "table.npz"
    atomic_bytes(target, b"old")

    def interrupted() -> None:
        with atomic_path(target, ".npz") as temporary:
            np.savez(temporary, a=np.arange(3))
            raise KeyboardInterrupt  # Ctrl-C after the temporary file was written

    with pytest.raises(KeyboardInterrupt):
        interrupted()
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["table.npz"]
    with atomic_path(target, ".npz") as temporary:
        np.savez(temporary, a=np.arange(3))
    with np.load(target) as data:
        assert data["a"].tolist() == [0, 1, 2]
    assert target.stat().st_mode & 0o777 == _usual_mode()


def test_durable_text_and_bytes_read_back(tmp_path: Path) -> None:
    with atomic_text(tmp_path / "a.txt", durable=True) as stream:
        stream.write("line\r\n")  # no newline translation
    assert (tmp_path / "a.txt").read_bytes() == b"line\r\n"
    atomic_bytes(tmp_path / "b.bin", bytes(range(4)))
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01\x02\x03"


def test_a_missing_directory_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere"
    with pytest.raises(FileNotFoundError, match=r"directory .*nowhere does not exist"):
        atomic_bytes(missing / "x.csv", b"")
    assert not missing.exists()


def test_a_failed_write_names_the_file(tmp_path: Path) -> None:
    """A write error carries no file name (``[Errno 28] No space left on device``): the target is
    added, so the user learns which output could not be written."""
    target = tmp_path / "report.html"
    target.write_text("old")

    def disk_full() -> None:
        with atomic_text(target) as stream:
            stream.write("half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # what a full disk raises

    def missing_input() -> None:
        with atomic_path(target) as temporary:
            (temporary.parent / "gone" / "x").read_bytes()

    with pytest.raises(OSError, match="No space left on device") as caught:
        disk_full()
    assert caught.value.filename == str(target)
    assert str(target) in str(caught.value)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    with pytest.raises(FileNotFoundError) as missing:  # an error naming its file keeps it
        missing_input()
    assert missing.value.filename == str(tmp_path / "gone" / "x")


def test_a_figure_that_fails_half_way_leaves_nothing(tmp_path: Path) -> None:
    figure = Figure()
    figure.add_subplot().plot([0, 1], [1, 0])

    def disk_full(path: Path, **_: object) -> None:
        Path(path).write_bytes(b"\x89PNG half")
        raise OSError("No space left on device")

    real_savefig = figure.savefig
    figure.savefig = disk_full  # type: ignore[method-assign]
    with pytest.raises(OSError, match="No space left"):
        save_figure(figure, tmp_path / "plot.png")
    assert list(tmp_path.iterdir()) == []
    figure.savefig = real_savefig  # type: ignore[method-assign]
    path = save_figure(figure, tmp_path / "plot.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
