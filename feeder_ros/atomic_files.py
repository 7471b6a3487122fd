"""Files that appear complete or not at all.

Every writer of the project (CSV and JSON reports, figures, speed models, cached tables) writes to a
temporary file in the target's directory and renames it over the target (``os.replace``, atomic
on POSIX) only when the write has completed. A failure at any step, Ctrl-C included, leaves an
existing file untouched and no temporary file behind; a reader running at the same time sees the
old file or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import functools
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

__all__ = ["atomic_bytes", "atomic_path", "atomic_text"]


@functools.cache
def _file_mode() -> int:
    """The mode a plain ``open()`` gives a new file: 0666 without the process umask (read once:
    setting and restoring the umask is not safe while other threads create files)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


@contextlib.contextmanager
def atomic_path(path: Path | str, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path beside ``path`` for a writer that wants a file name (``savefig``,
    ``np.savez``); it is renamed onto ``path`` when the block completes and removed otherwise.

    Raises :class:`FileNotFoundError` naming the directory when it does not exist.
    """
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise FileNotFoundError(f"{target}: directory {directory} does not exist")
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=directory)
    os.close(fd)
    temporary = Path(name)
    try:
        yield temporary
        os.chmod(temporary, _file_mode())  # mkstemp creates 0600
        os.replace(temporary, target)
    except BaseException as error:
        temporary.unlink(missing_ok=True)
        if isinstance(error, OSError) and error.filename is None and error.errno is not None:
            error.filename = str(target)  # a failed write (disk full, I/O error) names no file
        raise


@contextlib.contextmanager
def atomic_text(path: Path | str, *, durable: bool = False) -> Iterator[TextIO]:
    """A UTF-8 text stream (no newline translation) that becomes ``path`` when the block
    completes; ``durable=True`` also flushes it to disk before the rename."""
    with atomic_path(path) as temporary, temporary.open("w", encoding="utf-8", newline="") as out:
        yield out
        if durable:
            out.flush()
            os.fsync(out.fileno())


def atomic_bytes(path: Path | str, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as temporary:
        temporary.write_bytes(data)
