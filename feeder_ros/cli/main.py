"""Entry point of the ``feeder`` command.

Each sub-command lives in its own module of :mod:`feeder_ros.cli` and exposes

* ``HELP``: a one-line summary shown by ``feeder --help``;
* ``EPILOG`` (optional): text after the options in ``feeder COMMAND --help``;
* ``add_arguments(parser)``: declares its options on an :class:`argparse.ArgumentParser`;
* ``run(args) -> int``: does the work (through library modules) and returns the exit status.

Errors the user can fix (bad parameters, unreadable files) are raised as :class:`CommandError`
(or :class:`ValueError` subclasses such as ``ParameterError``) and printed as one line, exit 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import Protocol, cast

from feeder_ros.physics.errors import SimulationError

__all__ = ["SUBCOMMANDS", "CommandError", "main"]

# name -> module (imported lazily so that ``feeder --help`` stays fast)
SUBCOMMANDS: dict[str, str] = {
    "sim": "feeder_ros.cli.sim",
    "cell": "feeder_ros.cli.cell",
    "record": "feeder_ros.cli.record",
    "analyze": "feeder_ros.cli.analyze",
    "info": "feeder_ros.cli.info",
    "reindex": "feeder_ros.cli.reindex",
    "identify": "feeder_ros.cli.identify",
    "design": "feeder_ros.cli.design",
}


class CommandError(Exception):
    """A failure the user can act on; printed without a traceback."""


class _Subcommand(Protocol):
    HELP: str

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


def _load(name: str) -> _Subcommand:
    return cast(_Subcommand, importlib.import_module(SUBCOMMANDS[name]))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="feeder",
        description="Vibratory inline feeder tools: simulate, run a cell, record and analyse bags.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in SUBCOMMANDS:
        module = _load(name)
        child = sub.add_parser(
            name, help=module.HELP, description=module.HELP, epilog=getattr(module, "EPILOG", None)
        )
        module.add_arguments(child)
        child.set_defaults(_run=module.run, _parser=child)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # said by the sub-command's parser: its usage and name, exit status 2
        args._parser.error(f"unrecognized arguments: {' '.join(extra)}")
    try:
        return int(args._run(args))
    except KeyboardInterrupt:
        print("feeder: interrupted", file=sys.stderr)
        return 130
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
