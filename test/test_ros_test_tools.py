"""The test harness: the probe node (a spinning thread that dies fails the test, except in
shutdown) and its service calls (a lost answer is asked for again only where that is safe)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import rclpy
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor
from ros_test_tools import call, probe_node, wait_until
from std_srvs.srv import Trigger


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


@contextmanager
def server_losing_its_first_answer(service_type: Any, name: str) -> Iterator[list[float]]:
    """A service in its own context whose first request is answered only after the test has
    left (as if the reply were lost); later requests are answered at once. Yields the arrival
    times of the requests."""
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("harness_server", context=context)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    arrivals: list[float] = []
    release = threading.Event()

    def answer(request: Any, response: Any) -> Any:
        arrivals.append(time.monotonic())
        number = len(arrivals)
        if number == 1:
            release.wait(timeout=30.0)
        if service_type is GetParameters:
            value = ParameterValue(type=ParameterType.PARAMETER_STRING)
            value.string_value = f"answer {number}"
            response.values = [value]
        return response

    node.create_service(service_type, name, answer, callback_group=ReentrantCallbackGroup())
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        yield arrivals
    finally:
        release.set()
        executor.shutdown()
        thread.join(timeout=5)
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_a_lost_answer_to_a_repeatable_request_is_asked_for_again() -> None:
    name = "/harness_lost_answer/get_parameters"
    with server_losing_its_first_answer(GetParameters, name) as arrivals, probe_node() as probe:
        start = time.monotonic()
        answer = call(probe, GetParameters, name, GetParameters.Request(), 20.0, attempt_s=1.0)
        took = time.monotonic() - start
    assert [value.string_value for value in answer.values] == ["answer 2"]
    assert len(arrivals) == 2
    # Sent again only when the attempt window ran out: the second request left the probe at
    # least 1 s after the call began. (The gap between the two arrivals can be shorter: the
    # first request may spend longer on the way than the second.)
    assert arrivals[1] - start >= 1.0
    assert arrivals[0] <= arrivals[1]
    assert took < 20.0


def test_a_request_that_may_act_twice_is_sent_once() -> None:
    name = "/harness_lost_answer/start"
    with server_losing_its_first_answer(Trigger, name) as arrivals, probe_node() as probe:
        with pytest.raises(AssertionError, match=f"{name} did not answer within 2.0 s"):
            call(probe, Trigger, name, Trigger.Request(), 2.0, attempt_s=0.5)
        time.sleep(1.0)  # a second request would have arrived by now
        assert len(arrivals) == 1
