"""The nodes log through ``RcutilsLogger.warning``, never its ``warn`` alias.

rclpy keys a log call's filters (``throttle_duration_sec``, ``once``) by its caller. Through
Kilted's deprecated ``warn``, the caller is the deprecation wrapper, so every ``warn`` of a process
shares one context: a throttled warning silenced the others for its interval, and a ``warn``
without a throttle after a throttled one raised ``ValueError`` ("Requested logging filters cannot
be changed between calls") inside the node's callback. Both are shown here (Jazzy's ``warn`` is
harmless), and no ``warn`` call is left, so the nodes are right on both distributions.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context

from feeder_ros.ros_compat import RCLPY_MAJOR_BY_DISTRO, rclpy_major

ROOT = Path(__file__).resolve().parents[1]


def _warn_calls(path: Path) -> list[int]:
    tree = ast.parse(path.read_text(), filename=str(path))
    return [
        node.lineno
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Attribute)
        and node.func.attr == "warn"
        and not (isinstance(node.func.value, ast.Name) and node.func.value.id == "warnings")
    ]


def test_no_logger_warn_call_is_left() -> None:
    sources = list(ROOT.joinpath("feeder_ros").rglob("*.py"))
    found = {str(p.relative_to(ROOT)): lines for p in sources if (lines := _warn_calls(p))}
    assert not found, f"logger.warn( calls (use .warning): {found}"


def test_warn_shares_one_filter_context_on_kilted_and_warning_never_does() -> None:
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("logging_calls_probe", context=context)
        logger = node.get_logger()
        if rclpy_major() == RCLPY_MAJOR_BY_DISTRO["kilted"]:
            with pytest.warns(DeprecationWarning, match="warning"):
                assert logger.warn("first", throttle_duration_sec=5.0)
            with (
                pytest.warns(DeprecationWarning, match="warning"),
                pytest.raises(ValueError, match="filters cannot be changed"),
            ):
                logger.warn("second, no throttle")  # another call site, the same context
        else:  # Jazzy finds the caller past rclpy's own frames: each warn site is its own
            assert logger.warn("first", throttle_duration_sec=5.0)
            assert logger.warn("second, no throttle")
        assert logger.warning("third", throttle_duration_sec=5.0)
        assert logger.warning("fourth, another site", throttle_duration_sec=5.0)
        assert logger.warning("fifth, no throttle")
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
