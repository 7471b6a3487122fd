"""``StopOnShutdown``: which errors out of a spin loop are the stop that was asked for."""

from __future__ import annotations

import threading
import time
from typing import Any, cast

import pytest
from rclpy.executors import ExternalShutdownException

from feeder_ros.nodes.runner import StopOnShutdown


class FakeContext:
    """A context whose ``ok()`` turns false ``down_after_s`` after it was made (None: never)."""

    def __init__(self, down_after_s: float | None) -> None:
        self._down = threading.Event()
        if down_after_s is not None:
            threading.Timer(down_after_s, self._down.set).start()

    def ok(self) -> bool:
        return not self._down.is_set()


def _guard(down_after_s: float | None) -> StopOnShutdown:
    return StopOnShutdown(cast(Any, FakeContext(down_after_s)))


@pytest.mark.parametrize("error", [KeyboardInterrupt, ExternalShutdownException])
def test_a_signal_is_a_stop(error: type[BaseException]) -> None:
    guard = _guard(None)
    guard.shutdown_wait_s = 0.1
    with guard:
        raise error()
    assert guard.stopped


def test_a_ctrl_c_ends_the_block_once_the_signal_thread_shut_the_context_down() -> None:
    # the KeyboardInterrupt comes first; rclpy's signal thread triggers the executors' guard
    # conditions and shuts the context down after it: nothing may be torn down before that
    context = FakeContext(0.2)
    guard = StopOnShutdown(cast(Any, context))
    with guard:
        raise KeyboardInterrupt
    assert not context.ok()
    assert guard.stopped


def test_a_ctrl_c_without_rclpys_handlers_still_stops_after_the_wait() -> None:
    guard = _guard(None)
    guard.shutdown_wait_s = 0.2
    started = time.monotonic()
    with guard:
        raise KeyboardInterrupt
    assert guard.stopped
    assert time.monotonic() - started >= 0.2


def test_a_take_failing_just_before_the_signals_shutdown_shows_is_a_stop() -> None:
    # rclpy's signal thread shuts the context down a moment after the take failed on it
    guard = _guard(0.05)
    with guard:
        raise RuntimeError("Unable to convert call argument '0' to Python object")
    assert guard.stopped


def test_a_runtime_error_without_a_shutdown_propagates() -> None:
    guard = _guard(None)
    guard.shutdown_wait_s = 0.1
    started = time.monotonic()
    with pytest.raises(RuntimeError, match="a real failure"), guard:
        raise RuntimeError("a real failure")
    assert not guard.stopped
    assert time.monotonic() - started >= 0.1  # it waited for a shutdown that did not come


def test_other_errors_propagate_at_once() -> None:
    guard = _guard(0.0)
    time.sleep(0.01)
    with pytest.raises(ValueError, match="bad"), guard:
        raise ValueError("bad")
    assert not guard.stopped
