"""Output paths of the sub-commands, checked before any work is done.

A run that fails on its output only after minutes of work, or after writing some of its files,
is worse than one refused at once. The rules, the same for every sub-command:

* an output **file** (``--output x.csv``, ``--model-out m.yaml``) must not be a directory, and
  its directory must exist;
* an output **directory** (``--output DIR``, ``--plot DIR``) must not be a file; it is created
  (with its parents) when written, so the nearest existing ancestor must be a directory we may
  write in; ``DIR/.feeder-outputs``, if there, must be a file (see below).

A directory written again holds only this run's files: a run records the names it wrote in
``.feeder-outputs`` there, and the next run into it removes those of them it did not write again
(a fit, a plot or a bag's tables from an earlier run would otherwise sit beside new results and
contradict them). Files it did not write itself are never touched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from feeder_ros.atomic_files import atomic_text
from feeder_ros.cli.main import CommandError

__all__ = [
    "MANIFEST_NAME",
    "check_output_dir",
    "check_output_file",
    "finish_output_dir",
    "replace_earlier_outputs",
]

#: the file in an output directory that names the files the last run wrote there
MANIFEST_NAME = ".feeder-outputs"


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
    record = path / MANIFEST_NAME
    if not record.is_symlink() and record.exists() and not record.is_file():
        # the run would write everything and then fail on its record of what it wrote
        raise CommandError(
            f"{option} {path}: {record} is not a file (the name is kept for the record of the"
            " files a run writes there)"
        )
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


def finish_output_dir(directory: Path, written: Iterable[Path]) -> None:
    """:func:`replace_earlier_outputs`, saying on stdout which files it removed."""
    removed = replace_earlier_outputs(directory, written)
    if removed:
        print(
            f"removed {len(removed)} file(s) an earlier run wrote to {directory} and this one "
            f"did not: {', '.join(removed)}"
        )


def _plain_name(name: str) -> bool:
    return name not in ("", ".", "..", MANIFEST_NAME) and "/" not in name and os.sep not in name
