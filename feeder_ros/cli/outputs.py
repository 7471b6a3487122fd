"""Output paths of the sub-commands, checked before any work is done.

A run that fails on its output only after minutes of work, or after writing some of its files,
is worse than one refused at once. Files are written as :mod:`feeder_ros.atomic_files` says (a
temporary file renamed onto the target; a symbolic link followed, its target replaced and the link
kept; a FIFO or a character device written in place). The rules, the same for every sub-command:

* an output **file** (``--output x.csv``, ``--model-out m.yaml``) must be a regular file, a new
  one, or a link to either, whose directory exists; a dangling link is written through to its
  target when the target's directory exists. A directory, a socket or a block device is refused;
* a **stream** output (text written once, front to back: ``feeder sim --output`` and
  ``--events``) may also be standard output: ``-``, ``/dev/stdout`` (or ``/dev/fd/1``, or any path
  to the file standard output is on) writes to standard output, and the command's own report then
  goes to standard error; ``/dev/stderr`` (``/dev/fd/2``) writes to standard error. A FIFO or a
  character device (a terminal, ``/dev/null``) is written in place. Two outputs on one standard
  stream are refused;
* an output that is read back **by name** (``--model-out``, ``--params-out``) must be a file:
  standard output, a FIFO or a device is refused with the reason;
* an output **directory** (``--output DIR``, ``--plot DIR``) must not be a file, nor standard
  output (a directory of PNG, CSV, ... cannot be streamed); it is created (with its parents) when
  written, so the nearest existing ancestor must be a directory we may write in;
  ``DIR/.feeder-outputs``, if there, must be a regular file (see below);
* nothing is written into a **bag directory** (``metadata.yaml`` or ``.mcap`` files in it, as
  :class:`feeder_ros.bag.Bag` reads one): an output directory that is one, and an output file
  whose directory is one (after following links), are refused; so is an output directory that is
  (or lies in) one of the command's input bags. A subdirectory of a bag is not the bag (its
  reader does not look into subdirectories).

A directory written again holds only this run's files: a run records the names it wrote in
``.feeder-outputs`` there, and the next run into it removes those of them it did not write again
(a fit, a plot or a bag's tables from an earlier run would otherwise sit beside new results and
contradict them). Files it did not write itself are never touched.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import TextIO

from feeder_ros.atomic_files import atomic_text, write_target
from feeder_ros.cli.main import CommandError

__all__ = [
    "MANIFEST_NAME",
    "check_apart_from_inputs",
    "check_output_dir",
    "check_output_file",
    "finish_output_dir",
    "is_bag_directory",
    "open_output_text",
    "output_path",
    "replace_earlier_outputs",
    "report_stream",
    "standard_stream",
]

#: the file in an output directory that names the files the last run wrote there
MANIFEST_NAME = ".feeder-outputs"

#: the names of standard output (file descriptor 1) and standard error (2)
_STANDARD_NAMES: dict[str, int] = {
    "-": 1,
    "/dev/stdout": 1,
    "/dev/fd/1": 1,
    "/proc/self/fd/1": 1,
    "/dev/stderr": 2,
    "/dev/fd/2": 2,
    "/proc/self/fd/2": 2,
}
_STREAM_NAMES = {1: "standard output", 2: "standard error"}


def output_path(text: str) -> Path:
    """argparse ``type=`` of an output option. ``-`` is standard output; a path that reads as
    ``-`` only once normalised (``./-``: pathlib drops the ``./``) is the file of that name in the
    current directory, so it is made absolute."""
    path = Path(text)
    if text != "-" and str(path) == "-":
        return Path.cwd() / "-"
    return path


def _named_standard_fd(path: Path) -> int | None:
    """1 or 2 when ``path`` is one of the names of standard output or error."""
    return _STANDARD_NAMES.get(str(path))


def _standard_fd(path: Path) -> int | None:
    """1 or 2 when writing ``path`` means writing standard output or error: one of their names,
    or a path to the very file one of them is on (a link to ``/dev/stdout``, the pipe itself)."""
    named = _named_standard_fd(path)
    if named is not None:
        return named
    try:
        status = os.stat(path)
    except (OSError, ValueError):
        return None
    for fd in (1, 2):
        try:
            other = os.fstat(fd)
        except OSError:  # closed
            continue
        if (status.st_dev, status.st_ino) == (other.st_dev, other.st_ino):
            return fd
    return None


def standard_stream(path: Path | None) -> TextIO | None:
    """The standard stream a stream output ``path`` writes to (see the module's rules), or None:
    a file."""
    fd = None if path is None else _standard_fd(path)
    return None if fd is None else (sys.stdout if fd == 1 else sys.stderr)


@contextlib.contextmanager
def open_output_text(path: Path) -> Iterator[TextIO]:
    """A stream output opened for writing: its standard stream (flushed at the end), or
    :func:`~feeder_ros.atomic_files.atomic_text` (a FIFO or a device written in place)."""
    stream = standard_stream(path)
    if stream is None:
        with atomic_text(path) as out:
            yield out
        return
    yield stream
    stream.flush()


def report_stream(outputs: Sequence[tuple[str, Path | None]]) -> TextIO:
    """Where a command prints its own report, given its stream outputs ``(option, path)``:
    standard output, or standard error when an output goes to standard output. Refuses two
    outputs on one standard stream (their lines would interleave)."""
    taken: dict[int, str] = {}
    for option, path in outputs:
        fd = None if path is None else _standard_fd(path)
        if fd is None:
            continue
        if fd in taken:
            raise CommandError(
                f"{taken[fd]} and {option} {path} both write to {_STREAM_NAMES[fd]}: "
                "give one of them a file"
            )
        taken[fd] = f"{option} {path}"
    return sys.stderr if 1 in taken else sys.stdout


def is_bag_directory(path: Path) -> bool:
    """``path`` is a directory that reads as a bag (:class:`feeder_ros.bag.Bag`): it holds a
    ``metadata.yaml`` or ``.mcap`` files."""
    if not path.is_dir():
        return False
    if (path / "metadata.yaml").is_file():
        return True
    return any(p.is_file() for p in path.glob("*.mcap"))


def _bag_refusal(path: Path, option: str, given: Path) -> CommandError:
    return CommandError(
        f"{option} {given}: {path} is a bag directory (metadata.yaml or .mcap files): nothing is "
        "written into a bag; give a path outside it"
    )


def check_output_file(path: Path | None, option: str, *, by_name: str | None = None) -> None:
    """Refuse (``CommandError`` naming ``option`` and the path) a file output that cannot be
    written; None (option not given) passes.

    ``by_name``: why this output must be a file (it is read back by name); standard output, a
    FIFO or a device are then refused with this reason. None: a stream output, which may be
    standard output or error, a FIFO or a character device."""
    if path is None:
        return
    if by_name is None and _standard_fd(path) is not None:
        return
    named = _named_standard_fd(path)
    if named is not None:
        raise CommandError(f"{option} {path}: is {_STREAM_NAMES[named]}, not a file: {by_name}")
    if str(path) == "" or path.name in ("", ".", ".."):
        raise CommandError(f"{option} {str(path)!r}: not a file name")
    try:
        target = write_target(path)
    except OSError as error:
        raise CommandError(f"{option} {path}: {error.strerror}") from None
    if target.stream:
        if by_name is not None:
            raise CommandError(f"{option} {path}: is {target.kind}, not a file: {by_name}")
        if not os.access(path, os.W_OK):
            raise CommandError(f"{option} {path}: {target.kind} we may not write to")
        return
    directory = target.path.parent
    if is_bag_directory(directory):
        raise _bag_refusal(directory, option, path)
    _probe(directory, f"{option} {path}")


def check_output_dir(path: Path | None, option: str, *, holds: str = "output files") -> None:
    """Refuse a directory output that cannot be created or written, or is a bag; None
    passes. ``holds``: what the directory receives (said when standard output is given)."""
    if path is None:
        return
    if str(path) == "":
        raise CommandError(f"{option} '': not a directory name")
    named = _named_standard_fd(path)
    if named is not None:
        raise CommandError(
            f"{option} {path}: {_STREAM_NAMES[named]} cannot take a directory of {holds}; "
            "give a directory"
        )
    if path.exists() and not path.is_dir():
        raise CommandError(f"{option} {path}: exists and is not a directory")
    real = Path(os.path.realpath(path))
    if path.is_symlink() and not path.exists():
        raise CommandError(
            f"{option} {path}: symbolic link to {real}, which does not exist; create that "
            "directory or give another"
        )
    if is_bag_directory(real):
        raise _bag_refusal(real, option, path)
    if path.is_dir():
        _check_record(path, option)
    ancestor = path.absolute()
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise CommandError(f"{option} {path}: {ancestor} is not a directory")
    _probe(ancestor, f"{option} {path}")


def _check_record(directory: Path, option: str) -> None:
    """``directory/.feeder-outputs`` must be a regular file or absent: the run would write
    everything and then fail on its record of what it wrote (or wait on a FIFO forever)."""
    record = directory / MANIFEST_NAME
    try:
        target = write_target(record)
    except OSError as error:
        detail = error.strerror
    else:
        if not target.stream:
            return
        detail = f"is {target.kind}"
    raise CommandError(
        f"{option} {directory}: {record} is not a file ({detail}): the name is kept for the "
        "record of the files a run writes there"
    )


def check_apart_from_inputs(output: Path | None, option: str, inputs: Iterable[Path]) -> None:
    """Refuse an output directory that is one of the input bags ``inputs`` (a directory, its
    ``metadata.yaml`` or an ``.mcap`` file) or lies inside one; None passes."""
    if output is None:
        return
    real = Path(os.path.realpath(output))
    for bag in inputs:
        place = Path(os.path.realpath(bag.parent if bag.name == "metadata.yaml" else bag))
        if real == place:
            raise CommandError(
                f"{option} {output}: is the input bag {bag}; give another directory for the outputs"
            )
        if place in real.parents:
            raise CommandError(
                f"{option} {output}: lies inside the input bag {bag}; give a directory outside it"
            )


def _probe(directory: Path, what: str) -> None:
    """Create and remove an entry in ``directory``: the only sure test that we may write there
    (``os.access`` says yes to root on read-only file systems and on /proc)."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".feeder-probe-", dir=directory))
    except OSError as error:
        raise CommandError(f"{what}: cannot write in {directory}: {error.strerror}") from None


def replace_earlier_outputs(directory: Path, written: Iterable[Path]) -> list[str]:
    """After a run has written ``written`` into ``directory``: remove the files an earlier run
    recorded there and this one did not write, record this run's, and return the names removed.

    Only plain file names from the record are removed, never a directory or a link, so a record
    edited by hand cannot reach outside ``directory``. A file that cannot be removed stays
    recorded (the next run tries again)."""
    here = directory.resolve()
    names = {p.name for p in written if p.parent.resolve() == here}
    manifest = directory / MANIFEST_NAME
    earlier: list[str] = []
    # no record, or an unreadable one: nothing known to be ours
    with contextlib.suppress(OSError, UnicodeDecodeError):
        earlier = manifest.read_text(encoding="utf-8").splitlines()
    removed: list[str] = []
    kept: list[str] = []
    for name in dict.fromkeys(earlier):
        if name in names or not _plain_name(name):
            continue
        path = directory / name
        if path.is_symlink() or not path.is_file():
            continue
        try:
            path.unlink()
        except OSError:
            kept.append(name)
        else:
            removed.append(name)
    with atomic_text(manifest) as stream:
        stream.writelines(f"{name}\n" for name in sorted({*names, *kept}))
    return removed


def finish_output_dir(
    directory: Path, written: Iterable[Path], report: TextIO | None = None
) -> None:
    """:func:`replace_earlier_outputs`, saying on ``report`` (default: standard output) which
    files it removed."""
    removed = replace_earlier_outputs(directory, written)
    if removed:
        print(
            f"removed {len(removed)} file(s) an earlier run wrote to {directory} and this one "
            f"did not: {', '.join(removed)}",
            file=report,
        )


def _plain_name(name: str) -> bool:
    return name not in ("", ".", "..", MANIFEST_NAME) and "/" not in name and os.sep not in name
