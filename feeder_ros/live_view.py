"""The live view behind ``feeder view``: a running feeder's topics served to Foxglove (or any client
of the Foxglove WebSocket protocol) as they arrive.

:class:`FoxgloveSink` is a :class:`~feeder_ros.recording.TopicSink` on ``foxglove-sdk``'s server:
each topic becomes a channel with its ``ros2msg`` schema (the ``.msg`` text and its dependencies,
as rosbag2 stores it) and ``cdr`` message encoding, and each message is handed over as the CDR
bytes the subscription received: nothing is decoded or re-encoded, so Foxglove shows exactly what
is on the wire. Log times are the view's node clock at reception (simulated time with
``use_sim_time``). The server listens on localhost unless told otherwise: it has no
authentication, so serving on another interface exposes the cell's data to that network.

:func:`serve` discovers and subscribes to the topics as :func:`feeder_ros.recording.record` does
(everything under a namespace plus ``/diagnostics``, or a list; a QoS every publisher matches) and
runs until Ctrl-C, SIGTERM or its duration.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # rclpy: imported when a view is served, not by the CLI's help
    from feeder_ros.recording import TopicSelection

__all__ = ["DEFAULT_PORT", "LOCALHOST", "FoxgloveSink", "LiveViewError", "ViewSummary", "serve"]

DEFAULT_PORT = 8765  #: Foxglove's default WebSocket port
LOCALHOST = "127.0.0.1"


class LiveViewError(RuntimeError):
    """The server could not start (the port taken, the host unknown) or, stopped, did not free
    its port; the message says which."""


class FoxgloveSink:
    """A Foxglove WebSocket server on ``host:port`` (``port`` 0: any free port, see :attr:`port`)
    with one ``cdr`` channel per added topic. Thread-safe; :meth:`close` stops the server and may
    be called more than once."""

    def __init__(self, host: str = LOCALHOST, port: int = DEFAULT_PORT, name: str = "feeder_ros"):
        import foxglove  # the live view's own dependency: loaded only when a view is served

        self._foxglove = foxglove
        self._context = foxglove.Context()
        self._lock = threading.Lock()
        self._channels: dict[str, Any] = {}
        try:
            self._server: Any = foxglove.start_server(
                name=name, host=host, port=port, context=self._context
            )
        except RuntimeError as error:  # foxglove.FoxgloveError: bind failures, bad hosts
            raise LiveViewError(f"cannot serve the live view on {host}:{port}: {error}") from None
        self.host = host
        self.port = int(self._server.port)
        self._stopped = False

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    @property
    def topics(self) -> list[str]:
        with self._lock:
            return sorted(self._channels)

    def add_topic(self, name: str, type_name: str, offered_qos_profiles: str = "") -> None:
        """Advertise ``name`` with the ``ros2msg`` schema of ``type_name`` (``pkg/msg/Type``); an
        unknown type raises ``UnknownTypeError`` naming it. ``offered_qos_profiles`` is
        kept as the channel's metadata, as a bag keeps it."""
        from feeder_ros.bag.schemas import ros2msg_schema  # loaded when a view is served

        with self._lock:  # checked before advertising: clients never see a channel come and go
            if name in self._channels:
                raise ValueError(f"topic {name} is already served")
            schema = ros2msg_schema(type_name).encode("utf-8")
            self._channels[name] = self._foxglove.Channel(
                name,
                schema=self._foxglove.Schema(name=type_name, encoding="ros2msg", data=schema),
                message_encoding="cdr",
                context=self._context,
                metadata={"offered_qos_profiles": offered_qos_profiles},
            )

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send one message's CDR bytes to the clients subscribed to ``topic``."""
        self._channels[topic].log(data, log_time=log_time_ns)

    def close(self) -> None:
        """Close the channels and stop the server; once this returns the port is free (a new
        server may take it; a client's connection is refused). ``foxglove-sdk``'s ``stop``
        returns before its listener has closed: a connection right after it was accepted and
        dropped (CI; 6 of 200 here), so the port is watched until it can be bound, up to
        :attr:`release_limit_s` (then :class:`LiveViewError`, naming it)."""
        with self._lock:
            channels, self._channels = list(self._channels.values()), {}
            stopping, self._stopped = not self._stopped, True
        for channel in channels:
            channel.close()
        if not stopping:
            return
        self._server.stop()
        if not _port_released(self.host, self.port, self.release_limit_s):
            raise LiveViewError(
                f"the live view's port {self.host}:{self.port} was still taken "
                f"{self.release_limit_s:g} s after its server stopped"
            )

    #: how long :meth:`close` waits for the stopped server's listener to close [s]
    release_limit_s = 2.0


def _port_released(host: str, port: int, limit_s: float) -> bool:
    """Whether a socket can bind ``host:port`` (as a new server's would, ``SO_REUSEADDR``)
    within ``limit_s``: no listener holds it any more."""
    family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
    deadline = time.monotonic() + limit_s
    while True:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                probe.bind((host, port))
                return True
            except OSError:
                if time.monotonic() > deadline:
                    return False
        time.sleep(0.005)


@dataclass(frozen=True)
class ViewSummary:
    url: str
    counts: dict[str, int]
    skipped: dict[str, str]
    stopped_by: str

    def text(self) -> str:
        lines = [
            f"served {sum(self.counts.values())} message(s) on {len(self.counts)} topic(s) "
            f"at {self.url}; stopped by {self.stopped_by}"
        ]
        lines += [f"  not served: {t}: {why}" for t, why in sorted(self.skipped.items())]
        return "\n".join(lines)


def serve(
    options: TopicSelection,
    host: str = LOCALHOST,
    port: int = DEFAULT_PORT,
    args: Sequence[str] | None = None,
    on_ready: Callable[[FoxgloveSink], None] | None = None,
) -> ViewSummary:
    """Serve the topics ``options`` selects until Ctrl-C, SIGTERM or its duration. Raises
    :class:`LiveViewError` if the server cannot start; ``on_ready(sink)`` once it listens and the
    node is up."""
    from feeder_ros.recording import Forwarded, forward  # rclpy: only when a view is served

    sink = FoxgloveSink(host, port)
    forwarded = Forwarded()
    ready = None if on_ready is None else (lambda: on_ready(sink))
    forward(sink, options, forwarded, ("feeder_live_view", "serving"), args, ready)
    return ViewSummary(
        sink.url, dict(forwarded.counts), dict(forwarded.skipped), forwarded.stopped_by
    )
