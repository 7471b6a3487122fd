"""argparse ``type=`` converters shared by the sub-commands: each refuses with the value named."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = [
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
