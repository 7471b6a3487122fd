"""A plain Foxglove WebSocket client for the live view's tests (``websockets``, not foxglove-sdk):
connects with the SDK's subprotocol, reads ``advertise``, subscribes and parses message frames
(opcode 1, subscription id u32, log time u64, little-endian, then the payload)."""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass
from typing import Any

from websockets.sync.client import ClientConnection, connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1


@dataclass(frozen=True)
class Frame:
    subscription: int
    log_time_ns: int
    payload: bytes


class FoxgloveClient:
    """``with FoxgloveClient(url) as client:`` connects; leaving the block closes."""

    def __init__(self, url: str) -> None:
        self.connection: ClientConnection = connect(url, subprotocols=[SUBPROTOCOL])
        self.connection.__enter__()
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> advertised channel
        self.frames: list[Frame] = []
        self._next_id = 1
        self.subscriptions: dict[int, str] = {}  # subscription id -> topic

    def _receive(self, timeout_s: float) -> None:
        message = self.connection.recv(timeout=timeout_s)
        if isinstance(message, bytes):
            opcode = message[0]
            if opcode == MESSAGE_DATA:
                subscription, log_time = struct.unpack_from("<IQ", message, 1)
                self.frames.append(Frame(subscription, log_time, bytes(message[13:])))
            return
        operation = json.loads(message)
        if operation.get("op") == "advertise":
            for channel in operation["channels"]:
                self.channels[channel["topic"]] = channel

    def wait_for(self, condition: Any, timeout_s: float) -> bool:
        """Read until ``condition()`` holds or ``timeout_s`` passes."""
        end = time.monotonic() + timeout_s
        while not condition():
            left = end - time.monotonic()
            if left <= 0.0:
                return False
            try:
                self._receive(min(left, 0.5))
            except TimeoutError:
                continue
        return True

    def subscribe(self, topic: str) -> int:
        subscription = self._next_id
        self._next_id += 1
        channel = self.channels[topic]["id"]
        self.connection.send(
            json.dumps(
                {"op": "subscribe", "subscriptions": [{"id": subscription, "channelId": channel}]}
            )
        )
        self.subscriptions[subscription] = topic
        return subscription

    def payloads(self, topic: str) -> list[Frame]:
        return [f for f in self.frames if self.subscriptions.get(f.subscription) == topic]

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.connection.__exit__(None, None, None)
