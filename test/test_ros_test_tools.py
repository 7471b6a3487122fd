"""The test harness's probe node: a spinning thread that dies fails the test, except in shutdown."""

from __future__ import annotations

import threading
import time

import pytest
from ros_test_tools import probe_node, wait_until


def test_a_probe_whose_spinning_thread_dies_fails_at_its_exit() -> None:
    calls: list[int] = []

    def tick() -> None:
        calls.append(1)
        raise RuntimeError("callback failed on purpose")

    with (  # noqa: PT012
        pytest.raises(AssertionError, match="thread died: RuntimeError"),
        probe_node() as node,
    ):
        node.create_timer(0.01, tick)
        assert wait_until(lambda: bool(calls), timeout_s=5.0)
        time.sleep(0.1)  # the error has left the executor's spin by now
    assert calls == [1]  # the thread stopped at the first error


def test_an_error_while_the_probe_shuts_down_is_only_printed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    entered = threading.Event()

    def tick() -> None:
        if entered.is_set():
            return
        entered.set()
        time.sleep(0.5)  # the test leaves the probe meanwhile: shutdown waits for this callback
        raise RuntimeError("callback failed during shutdown")

    with probe_node() as node:
        node.create_timer(0.01, tick)
        assert wait_until(entered.is_set, timeout_s=5.0)
    assert "failed while shutting down: RuntimeError" in capsys.readouterr().out
