"""Output paths of the sub-commands, checked before any work is done.

A run that fails on its output only after minutes of work, or after writing some of its files,
is worse than one refused at once. The rules, the same for every sub-command:

* an output **file** (``--output x.csv``, ``--model-out m.yaml``) must not be a directory, and
  its directory must exist;
* an output **directory** (``--output DIR``, ``--plot DIR``) must not be a file; it is created
  (with its parents) when written, so the nearest existing ancestor must be a directory we may
  write in.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from feeder_ros.cli.main import CommandError

__all__ = ["check_output_dir", "check_output_file"]


def check_output_file(path: Path | None, option: str) -> None:
    """Refuse (``CommandError`` naming ``option`` and the path) a file output that cannot be
    written; None (option not given) passes."""
    if path is None:
        return
    if str(path) == "" or path.name in ("", ".", ".."):
        raise CommandError(f"{option} {str(path)!r}: not a file name")
    if path.is_dir():
        raise CommandError(f"{option} {path}: is a directory")
    parent = path.parent
    if not parent.is_dir():
        raise CommandError(f"{option} {path}: directory {parent} does not exist")
    _probe(parent, f"{option} {path}")


def check_output_dir(path: Path | None, option: str) -> None:
    """Refuse a directory output that cannot be created or written; None passes."""
    if path is None:
        return
    if str(path) == "":
        raise CommandError(f"{option} '': not a directory name")
    if path.exists() and not path.is_dir():
        raise CommandError(f"{option} {path}: exists and is not a directory")
    ancestor = path.absolute()
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise CommandError(f"{option} {path}: {ancestor} is not a directory")
    _probe(ancestor, f"{option} {path}")


def _probe(directory: Path, what: str) -> None:
    """Create and remove an entry in ``directory``: the only sure test that we may write there
    (``os.access`` says yes to root on read-only file systems and on /proc)."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".feeder-probe-", dir=directory))
    except OSError as error:
        raise CommandError(f"{what}: cannot write in {directory}: {error.strerror}") from None
