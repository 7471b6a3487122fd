"""A service call from a thread other than the one spinning the node, that survives a lost answer.

A server can drop its answer: it sends it while it has not yet discovered the client's reply
reader (rmw: "failed to send response (timeout)"), and the request is then answered never. A new
client meets this race on its first calls, so a request that may run twice (a query, ``start``,
``stop``) is sent again after ``ask_again_s`` without an answer; one that must not (a lifecycle
transition, a new set point) is sent once and waits its whole timeout. Keep clients for the
node's life: once a server has answered a client, its reply path is known.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

__all__ = ["ServiceCallError", "call_service"]


class ServiceCallError(RuntimeError):
    """The service is not there, or did not answer in time (the message names it)."""


def call_service(
    client: Any,
    request: Any,
    timeout_s: float,
    ask_again_s: float | None = None,
    on_ask_again: Callable[[], None] | None = None,
) -> Any:
    """The answer of ``client``'s service to ``request`` within ``timeout_s`` (another thread
    spins the client's node). Unanswered after ``ask_again_s``: sent again (``None``: never),
    calling ``on_ask_again`` first. Raises :class:`ServiceCallError`."""
    name = client.service_name
    if not client.wait_for_service(timeout_sec=timeout_s):
        raise ServiceCallError(f"service {name} is not available")
    deadline = time.monotonic() + timeout_s
    while True:
        future = client.call_async(request)
        again = time.monotonic() + (ask_again_s if ask_again_s is not None else math.inf)
        while not future.done():
            now = time.monotonic()
            if now > deadline:
                client.remove_pending_request(future)
                raise ServiceCallError(f"service {name} did not answer in {timeout_s:g} s")
            if now > again:
                break
            time.sleep(0.005)
        if future.done():
            return future.result()
        client.remove_pending_request(future)
        if on_ask_again is not None:
            on_ask_again()
