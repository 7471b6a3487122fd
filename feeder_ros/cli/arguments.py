"""argparse ``type=`` converters shared by the sub-commands (each refuses with the value named),
and the options of the commands that take topics from a running graph."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = [
    "add_topic_selection",
    "int_at_least",
    "non_negative_float",
    "non_negative_int",
    "positive_float",
    "positive_int",
]


def _number(text: str, kind: Callable[[str], float], what: str) -> float:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} must be finite")
    return value


def positive_float(text: str) -> float:
    value = _number(text, float, "a number")
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be positive and finite")
    return value


def non_negative_float(text: str) -> float:
    value = _number(text, float, "a number")
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0 and finite")
    return value


def positive_int(text: str) -> int:
    value = int(_number(text, int, "an integer"))
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 1")
    return value


def non_negative_int(text: str) -> int:
    value = int(_number(text, int, "an integer"))
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0")
    return value


def int_at_least(minimum: int) -> Callable[[str], int]:
    """A converter for integers >= ``minimum``."""

    def convert(text: str) -> int:
        value = int(_number(text, int, "an integer"))
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{text!r} must be >= {minimum}")
        return value

    convert.__name__ = f"integer >= {minimum}"  # argparse names the type in some messages
    return convert


def add_topic_selection(parser: argparse.ArgumentParser, verb: str) -> None:
    """``TOPIC...``, ``--namespace``, ``--duration`` and ``--use-sim-time``, for a command that
    ``verb``s topics of the running graph (``feeder record``, ``feeder view``)."""
    parser.add_argument(
        "topics",
        nargs="*",
        metavar="TOPIC",
        help=f"topics to {verb} (relative names are taken in --namespace); "
        "default: every topic under --namespace, plus /diagnostics",
    )
    parser.add_argument(
        "--namespace", default="/", help="the feeder's namespace (default: /, every topic)"
    )
    parser.add_argument(
        "--duration",
        type=positive_float,
        metavar="S",
        help="stop after this many seconds, > 0 (default: until Ctrl-C)",
    )
    parser.add_argument(
        "--use-sim-time", action="store_true", help="log times from /clock instead of the wall"
    )
