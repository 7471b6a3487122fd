"""Entry point of the ``feeder`` command.

Each sub-command lives in its own module of :mod:`feeder_ros.cli` and exposes

* ``HELP``: a one-line summary shown by ``feeder --help``;
* ``EPILOG`` (optional): text after the options in ``feeder COMMAND --help``, paragraphs separated
  by blank lines: prose is wrapped to the terminal, a paragraph with indented lines (the
  ``examples:`` block every sub-command has) keeps its layout (:class:`HelpFormatter`);
* ``add_arguments(parser)``: declares its options on an :class:`argparse.ArgumentParser`;
* ``run(args) -> int``: does the work (through library modules) and returns the exit status.

Errors the user can fix (bad parameters, unreadable files) are raised as :class:`CommandError`
(or :class:`ValueError` subclasses such as ``ParameterError``) and printed as one line, exit 2.

Bare ``feeder`` prints the help on stdout and exits 0 (as ``ros2``, ``git`` or ``pip`` without a
command show what there is), ``feeder --version`` the version. Ctrl-C: a command whose work is
cut short by it (``feeder sim`` mid-run, ``feeder analyze``, a sweep) exits 130 (128 + SIGINT,
what a shell reports for a command killed by Ctrl-C); ``feeder cell``, ``feeder record`` and
``feeder view``, which run until stopped, take Ctrl-C as their normal end and exit 0 once the
cell's nodes are stopped, the bag or the server closed (their ``--help`` says so).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import textwrap
from collections.abc import Sequence
from typing import Protocol, cast

from feeder_ros.physics.errors import SimulationError

__all__ = ["DISTRIBUTION", "SUBCOMMANDS", "CommandError", "HelpFormatter", "main", "version"]

# name -> module (imported lazily so that ``feeder --help`` stays fast)
SUBCOMMANDS: dict[str, str] = {
    "sim": "feeder_ros.cli.sim",
    "cell": "feeder_ros.cli.cell",
    "record": "feeder_ros.cli.record",
    "view": "feeder_ros.cli.view",
    "analyze": "feeder_ros.cli.analyze",
    "info": "feeder_ros.cli.info",
    "reindex": "feeder_ros.cli.reindex",
    "identify": "feeder_ros.cli.identify",
    "design": "feeder_ros.cli.design",
    "completion": "feeder_ros.cli.completion",
}
DISTRIBUTION = "feeder_ros"  #: setup.py's name=, whose installed metadata has the version
INTERRUPTED = 130  #: exit status of a command Ctrl-C cut short (128 + SIGINT)

DESCRIPTION = "Vibratory inline feeder tools: simulate, run a cell, record and analyse bags."
EPILOG = """\
examples:
  # 2 s of the paper's case study with 3 parts, figures into figures/
  feeder sim --duration 2 --parts 3 --plot figures
  # the demo cell (config/cell.yaml) in one terminal, recorded in another (Ctrl-C ends
  # each), then analysed
  feeder cell
  feeder record --namespace /demo_cell/feeder_1 -o run1
  feeder analyze run1 --output report
  # tab completion of commands and options in this shell
  source <(feeder completion bash)

Run 'feeder COMMAND --help' for a command's options and examples.

Exit status: 0 done; 1 the work failed or is incomplete (a simulation failed, a bag lost data, a
node died: the command says what); 2 bad usage or input; 130 interrupted by Ctrl-C before the
work was done. 'feeder cell', 'feeder record' and 'feeder view' run until Ctrl-C (or SIGTERM),
their normal end: exit status 0 once the nodes are stopped, the bag or the server closed."""


class CommandError(Exception):
    """A failure the user can act on; printed without a traceback."""


class _Subcommand(Protocol):
    HELP: str

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions and epilogs by paragraph (blank-line separated): a paragraph with an indented
    line (an ``examples:`` block) keeps its layout, as RawDescriptionHelpFormatter keeps it;
    prose is wrapped to the terminal's width, as argparse's default does."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = []
        for paragraph in text.strip("\n").split("\n\n"):
            lines = paragraph.splitlines()
            if any(line[:1].isspace() for line in lines):
                paragraphs.append("\n".join(indent + line for line in lines))
            else:
                paragraphs.append(
                    textwrap.fill(
                        " ".join(paragraph.split()),
                        width,
                        initial_indent=indent,
                        subsequent_indent=indent,
                    )
                )
        return "\n\n".join(paragraphs)


def version() -> str:
    """The installed distribution's version; not installed (run from a source tree): the
    ``<version>`` of package.xml (the source tree's, else the installed share directory's)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as distribution_version

    try:
        return distribution_version(DISTRIBUTION)
    except PackageNotFoundError:
        pass
    from pathlib import Path
    from xml.etree import ElementTree

    for path in (
        Path(__file__).resolve().parents[2] / "package.xml",
        Path(sys.prefix) / "share" / DISTRIBUTION / "package.xml",
    ):
        try:
            text = ElementTree.parse(path).getroot().findtext("version")
        except (OSError, ElementTree.ParseError):
            continue
        if text and text.strip():
            return text.strip()
    return "unknown"


def _load(name: str) -> _Subcommand:
    return cast(_Subcommand, importlib.import_module(SUBCOMMANDS[name]))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="feeder", description=DESCRIPTION, epilog=EPILOG, formatter_class=HelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    # not required: bare ``feeder`` prints the help (main)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        module = _load(name)
        child = sub.add_parser(
            name,
            help=module.HELP,
            description=module.HELP,
            epilog=getattr(module, "EPILOG", None),
            formatter_class=HelpFormatter,
        )
        module.add_arguments(child)
        child.set_defaults(_run=module.run, _parser=child)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:
        # Ctrl-C cut the command short (while it loaded, or mid-run); ``feeder cell``,
        # ``feeder record`` and ``feeder view`` handle it themselves once started: for them it
        # is the normal end
        print("feeder: interrupted", file=sys.stderr)
        return INTERRUPTED


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if args.command is None:  # bare ``feeder``: what there is, on stdout
        if extra:
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
        parser.print_help()
        return 0
    if extra:  # said by the sub-command's parser: its usage and name, exit status 2
        args._parser.error(f"unrecognized arguments: {' '.join(extra)}")
    try:
        return int(args._run(args))
    except BrokenPipeError:
        # the reader went away (``feeder ... | head``): not an error to report; stdout goes to
        # devnull so that flushing it at exit does not raise again (Python's documented recipe)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (CommandError, ValueError, OSError) as error:
        print(f"feeder {args.command}: error: {error}", file=sys.stderr)
        return 2
    except SimulationError as error:  # the run itself failed (the parameters were valid)
        print(f"feeder {args.command}: simulation failed: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    # run as ``python -m feeder_ros.cli.main``: this file is then ``__main__``, a second copy of
    # the module whose CommandError is not the one the sub-commands raise; the package's own
    # module catches it
    from feeder_ros.cli.main import main as package_main

    sys.exit(package_main())
