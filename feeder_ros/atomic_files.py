"""Files that appear complete or not at all.

Every writer of the project (CSV and JSON reports, figures, speed models, cached tables) writes to a
temporary file in the target's directory and renames it over the target (``os.replace``, atomic
on POSIX) only when the write has completed. A failure at any step, Ctrl-C included, leaves an
existing file untouched and no temporary file behind; a reader running at the same time sees the
old file or the new one, never half of one.

What the path names decides what is written (:func:`write_target`):

* a **symbolic link** is followed, never replaced: the file it leads to (``os.path.realpath``) is
  the one replaced, through a temporary file in that file's directory, and the link stays as it
  was. A dangling link is written through (its target created) when the target's directory exists;
  otherwise, and for a loop of links, the write is refused naming the link;
* a **FIFO** or a **character device** (a terminal, ``/dev/null``) is a stream, not a file that can
  be replaced: it is opened and written in place (and not fsynced). A failed write leaves what was
  already written there: a stream keeps no old version;
* a **directory**, a **socket** or a **block device** is refused before anything is written
  (``OSError`` naming the path).

Standard output (``-``) is not a file name here: the command line decides what ``-`` means
(:mod:`feeder_ros.cli.outputs`).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import stat
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

__all__ = ["WriteTarget", "atomic_bytes", "atomic_path", "atomic_text", "file_kind", "write_target"]


@functools.cache
def _file_mode() -> int:
    """The mode a plain ``open()`` gives a new file: 0666 without the process umask (read once:
    setting and restoring the umask is not safe while other threads create files)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def file_kind(mode: int) -> str:
    """What an ``st_mode`` is, in words: 'a regular file', 'a FIFO', 'a socket', ..."""
    for test, kind in (
        (stat.S_ISREG, "a regular file"),
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return kind
    return "not a regular file"


@dataclass(frozen=True)
class WriteTarget:
    """Where a write to ``given`` goes (:func:`write_target`)."""

    given: Path
    #: the file written: a link's final target (replaced), or ``given`` itself for a stream
    path: Path
    #: a FIFO or a character device: opened and written in place, not replaced
    stream: bool
    #: 'a regular file', 'a FIFO', 'a character device', or 'a new file'
    kind: str


def write_target(path: Path | str) -> WriteTarget:
    """Where writing ``path`` goes: see the module's rules.

    Raises :class:`IsADirectoryError`, :class:`FileNotFoundError` (the directory, or a dangling
    link's target directory, does not exist), :class:`NotADirectoryError` or :class:`OSError` (a
    socket, a block device, a loop of links), each naming ``path`` and saying why.
    """
    given = Path(path)
    try:
        status: os.stat_result | None = os.stat(given)  # follows links, /proc/self/fd/N included
    except (FileNotFoundError, NotADirectoryError):
        status = None
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise OSError(errno.ELOOP, "a loop of symbolic links", str(given)) from None
        raise
    if status is not None:
        kind = file_kind(status.st_mode)
        if stat.S_ISFIFO(status.st_mode) or stat.S_ISCHR(status.st_mode):
            return WriteTarget(given, given, True, kind)  # opened through the link, if one
        if stat.S_ISDIR(status.st_mode):
            raise IsADirectoryError(errno.EISDIR, "is a directory", str(given))
        if not stat.S_ISREG(status.st_mode):
            raise OSError(
                errno.EINVAL,
                f"is {kind}: only a regular file, a FIFO or a character device can be written",
                str(given),
            )
        return WriteTarget(given, Path(os.path.realpath(given)), False, kind)
    target = Path(os.path.realpath(given))
    directory = target.parent
    if not directory.is_dir():
        where = f"directory {directory}"
        if given.is_symlink():
            where = f"symbolic link to {target}, whose directory {directory},"
        if directory.exists() or _under_a_file(directory):
            raise NotADirectoryError(errno.ENOTDIR, f"{where} is not a directory", str(given))
        raise FileNotFoundError(errno.ENOENT, f"{where} does not exist", str(given))
    return WriteTarget(given, target, False, "a new file")


def _under_a_file(path: Path) -> bool:
    """Some existing ancestor of ``path`` is not a directory."""
    return any(p.exists() and not p.is_dir() for p in path.parents)


def _name_the_file(error: BaseException, given: Path) -> None:
    if isinstance(error, OSError) and error.filename is None and error.errno is not None:
        error.filename = str(given)  # a failed write (disk full, I/O error) names no file


@contextlib.contextmanager
def _written(path: Path | str, suffix: str) -> Iterator[tuple[Path, bool]]:
    """(the path to write, whether it is a stream): a FIFO or a device itself, or a temporary
    file beside the target, renamed onto it when the block completes and removed otherwise."""
    target = write_target(path)
    if target.stream:
        try:
            yield target.path, True
        except BaseException as error:
            _name_the_file(error, target.given)
            raise
        return
    fd, name = tempfile.mkstemp(
        prefix=f".{target.path.name}.", suffix=suffix, dir=target.path.parent
    )
    os.close(fd)
    temporary = Path(name)
    try:
        yield temporary, False
        os.chmod(temporary, _file_mode())  # mkstemp creates 0600
        os.replace(temporary, target.path)
    except BaseException as error:
        temporary.unlink(missing_ok=True)
        _name_the_file(error, target.given)
        raise


@contextlib.contextmanager
def atomic_path(path: Path | str, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path beside ``path``'s target for a writer that wants a file name
    (``savefig``, ``np.savez``); it is renamed onto the target when the block completes and
    removed otherwise. A FIFO or a character device is given as it is (written in place).

    Raises :class:`FileNotFoundError` naming the directory when it does not exist, and the
    errors of :func:`write_target`.
    """
    with _written(path, suffix) as (written, _):
        yield written


@contextlib.contextmanager
def atomic_text(path: Path | str, *, durable: bool = False) -> Iterator[TextIO]:
    """A UTF-8 text stream (no newline translation) that becomes ``path`` when the block
    completes; ``durable=True`` also flushes it to disk before the rename (not a stream's)."""
    with (
        _written(path, ".tmp") as (written, stream),
        written.open("w", encoding="utf-8", newline="") as out,
    ):
        yield out
        if durable and not stream:
            out.flush()
            os.fsync(out.fileno())


def atomic_bytes(path: Path | str, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (in place to a FIFO or a character device)."""
    with _written(path, ".tmp") as (written, _), written.open("wb") as out:
        out.write(data)
