"""call_service without DDS: a client whose server drops answers, or answers late."""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future
from typing import Any

import pytest

from feeder_ros.nodes.service_calls import ServiceCallError, call_service


class LossyClient:
    """Answers request k (1-based) after ``delays[k-1]`` s; ``None``: the answer is lost."""

    service_name = "/cell/drive_interface/get_state"

    def __init__(self, delays: list[float | None], available: bool = True) -> None:
        self.delays = delays
        self.available = available
        self.sent = 0
        self.pending: list[Future[Any]] = []

    def wait_for_service(self, timeout_sec: float) -> bool:
        return self.available

    def call_async(self, request: Any) -> Future[Any]:
        self.sent += 1
        future: Future[Any] = Future()
        self.pending.append(future)
        k = self.sent
        delay = self.delays[k - 1] if k <= len(self.delays) else 0.0
        if delay is not None:
            threading.Timer(delay, future.set_result, args=(f"answer {k}",)).start()
        return future

    def remove_pending_request(self, future: Future[Any]) -> None:
        self.pending.remove(future)


def test_a_lost_answer_is_asked_for_again() -> None:
    client = LossyClient([None, 0.0])
    asked: list[float] = []
    start = time.monotonic()
    answer = call_service(client, "req", 5.0, 0.2, lambda: asked.append(time.monotonic() - start))
    assert (answer, client.sent, len(asked)) == ("answer 2", 2, 1)
    assert 0.2 <= asked[0] < 1.0
    # the lost request was given up (the fake keeps the answered one: rclpy drops it on answer)
    assert [f.result() for f in client.pending] == ["answer 2"]


def test_without_ask_again_one_request_waits_its_timeout() -> None:
    client = LossyClient([None])
    start = time.monotonic()
    with pytest.raises(
        ServiceCallError,
        match=r"service /cell/drive_interface/get_state did not answer in 0\.3 s",
    ):
        call_service(client, "req", 0.3)
    assert 0.3 <= time.monotonic() - start < 1.0
    assert (client.sent, client.pending) == (1, [])


def test_a_late_answer_within_the_wait_is_taken() -> None:
    client = LossyClient([0.1])
    assert call_service(client, "req", 5.0, 1.0) == "answer 1"
    assert client.sent == 1


def test_a_missing_service_is_named() -> None:
    with pytest.raises(ServiceCallError, match="get_state is not available"):
        call_service(LossyClient([], available=False), "req", 0.1)
