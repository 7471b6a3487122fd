"""The rclpy recorder behind ``feeder record`` (and ``feeder view``): serialized messages from the
graph into a bag (or a live view: any :class:`TopicSink`).

Topics are discovered on the graph (every ``discovery_period_s``): all topics under a namespace
(plus ``/diagnostics``), or an explicit list. Each is subscribed with ``raw=True`` (the CDR bytes
are written as they arrive, nothing is deserialised) and a QoS compatible with every publisher
(reliable only if all publishers are, transient-local only if all are); the publishers' offered
QoS profiles are stored per topic as rosbag2 does. The bag format, chunking, compression, splitting
and crash safety are :class:`~feeder_ros.bag.BagWriter`'s.

Log times are the node clock at reception (``use_sim_time`` gives simulated time). The recording
stops on Ctrl-C or SIGTERM (rclpy's signal handlers shut the context down) or after ``duration_s``;
in every case the bag is closed and its ``metadata.yaml`` final.
"""

from __future__ import annotations

import faulthandler
import importlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import yaml
from rclpy.duration import Duration
from rclpy.exceptions import InvalidNamespaceException, InvalidTopicNameException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.topic_endpoint_info import TopicEndpointInfo
from rclpy.validate_full_topic_name import validate_full_topic_name
from rclpy.validate_namespace import validate_namespace

from feeder_ros.bag import BagWriter
from feeder_ros.bag.errors import BagError
from feeder_ros.nodes import runner
from feeder_ros.nodes.runner import StopOnShutdown
from feeder_ros.ros_compat import RosSession

__all__ = [
    "IGNORED_TOPICS",
    "Forwarded",
    "RecordingOptions",
    "RecordingSummary",
    "TopicRecorder",
    "TopicSelection",
    "TopicSink",
    "forward",
    "offered_qos_yaml",
    "record",
    "selected",
]

IGNORED_TOPICS = frozenset({"/rosout", "/parameter_events"})
ALWAYS_WITH_NAMESPACE = ("/diagnostics",)
SUBSCRIPTION_DEPTH = 1000  # a second of history at 1 kHz before a slow write drops messages
_INFINITE_NS = 0x7FFF_FFFF_FFFF_FFFF


@dataclass(frozen=True)
class TopicSelection:
    """Which topics of the graph to take, and for how long (``feeder record``, ``feeder view``)."""

    topics: tuple[str, ...] = ()  # explicit topic names; empty: everything under ``namespace``
    namespace: str = "/"
    duration_s: float | None = None
    use_sim_time: bool = False
    discovery_period_s: float = 0.5

    def __post_init__(self) -> None:
        """Refuse (``ValueError`` naming the value) what cannot be taken: names that are not
        ROS names (nothing would ever match them), a duration that is not positive."""
        try:
            validate_namespace(_namespace(self.namespace))
        except InvalidNamespaceException as error:
            raise ValueError(f"namespace {self.namespace!r}: {error}") from None
        for topic in self.topics:
            full = topic if topic.startswith("/") else f"{_namespace(self.namespace)}/{topic}"
            try:
                validate_full_topic_name(full.replace("//", "/"))
            except InvalidTopicNameException as error:
                raise ValueError(f"topic {topic!r}: {error}") from None
        if self.duration_s is not None and not self.duration_s > 0.0:
            raise ValueError(f"duration_s={self.duration_s!r} must be > 0 (None: until Ctrl-C)")


@dataclass(frozen=True, kw_only=True)
class RecordingOptions(TopicSelection):
    """What to record and how to write it (see ``feeder record --help``)."""

    output: Path
    compression: str = "zstd"
    chunk_size: int = 1 << 20
    max_file_size: int = 0
    max_file_duration_s: float = 0.0


class TopicSink(Protocol):
    """Where the forwarded topics go: a bag (:class:`~feeder_ros.bag.BagWriter`), a live view.
    ``add_topic`` raises ``BagError``, ``OSError`` or ``ValueError`` for a topic it cannot take."""

    def add_topic(self, name: str, type_name: str, offered_qos_profiles: str) -> None: ...

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None: ...

    def close(self) -> None: ...


@dataclass
class Forwarded:
    """What a :class:`TopicRecorder` took: messages per topic, their types, the topics left out
    and why, and what stopped it."""

    counts: dict[str, int] = field(default_factory=dict)  # topic -> messages forwarded
    types: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)  # topic -> why it is not taken
    stopped_by: str = ""


@dataclass(kw_only=True)
class RecordingSummary(Forwarded):
    output: Path
    files: list[Path] = field(default_factory=list)

    def text(self) -> str:
        lines = [
            f"recorded {sum(self.counts.values())} message(s) on {len(self.counts)} topic(s) "
            f"into {self.output} ({len(self.files)} file(s)); stopped by {self.stopped_by}"
        ]
        lines += [f"  {t}: {n} ({self.types[t]})" for t, n in sorted(self.counts.items())]
        lines += [f"  not recorded: {t}: {why}" for t, why in sorted(self.skipped.items())]
        return "\n".join(lines)


def _namespace(ns: str) -> str:
    ns = "/" + ns.strip("/")
    return ns


def selected(name: str, options: TopicSelection) -> bool:
    """Whether a topic of the graph is taken under ``options``."""
    if options.topics:
        wanted = {
            t if t.startswith("/") else f"{_namespace(options.namespace).rstrip('/')}/{t}"
            for t in options.topics
        }
        return name in wanted
    if name in IGNORED_TOPICS:
        return False
    ns = _namespace(options.namespace)
    return ns == "/" or name.startswith(ns + "/") or name in ALWAYS_WITH_NAMESPACE


def _duration(value: Duration) -> dict[str, int]:
    ns = int(value.nanoseconds)
    if ns >= _INFINITE_NS or ns < 0:
        ns = _INFINITE_NS
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _policy(value: Any) -> str:
    return str(getattr(value, "name", value)).lower()


def offered_qos_yaml(publishers: Sequence[TopicEndpointInfo]) -> str:
    """The publishers' QoS profiles in rosbag2's ``offered_qos_profiles`` YAML form."""
    profiles = []
    for info in publishers:
        q = info.qos_profile
        profiles.append(
            {
                "history": _policy(q.history),
                "depth": int(q.depth),
                "reliability": _policy(q.reliability),
                "durability": _policy(q.durability),
                "deadline": _duration(q.deadline),
                "lifespan": _duration(q.lifespan),
                "liveliness": _policy(q.liveliness),
                "liveliness_lease_duration": _duration(q.liveliness_lease_duration),
                "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions),
            }
        )
    return str(yaml.safe_dump(profiles, sort_keys=False)) if profiles else "[]\n"


def subscription_qos(publishers: Sequence[TopicEndpointInfo]) -> QoSProfile:
    """A QoS that matches every publisher: reliable / transient local only if all offer it."""
    qos = [p.qos_profile for p in publishers]
    reliable = bool(qos) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in qos)
    latched = bool(qos) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in qos)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=SUBSCRIPTION_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def message_class(type_name: str) -> Any:
    """The Python class of ``pkg/msg/Type`` (the subscription needs it even for raw bytes)."""
    package, _, name = type_name.replace("/msg/", "/").partition("/")
    module = importlib.import_module(f"{package}.msg")
    return getattr(module, name)


class TopicRecorder(Node):
    """Subscribes (raw) to the selected topics as they appear and hands what arrives to a sink."""

    def __init__(
        self,
        sink: TopicSink,
        options: TopicSelection,
        summary: Forwarded,
        node_name: str = "feeder_recorder",
        verb: str = "recording",
    ) -> None:
        """``verb``: what the log lines say is done with a topic ("recording", "serving")."""
        super().__init__(
            node_name,
            parameter_overrides=[Parameter("use_sim_time", value=options.use_sim_time)],
        )
        self._sink = sink
        self._options = options
        self._summary = summary
        self._verb = verb
        self.discover()
        self.create_timer(options.discovery_period_s, self.discover)

    def discover(self) -> None:
        for name, types in self.get_topic_names_and_types():
            if (
                name in self._summary.counts
                or name in self._summary.skipped
                or not selected(name, self._options)
            ):
                continue
            if len(types) != 1:
                self._skip(name, f"several types on one topic: {', '.join(types)}")
                continue
            publishers = self.get_publishers_info_by_topic(name)
            if not publishers:
                continue  # only subscribers so far: wait for a publisher (and its QoS)
            try:
                cls = message_class(types[0])
                self._sink.add_topic(name, types[0], offered_qos_yaml(publishers))
            except (ImportError, AttributeError, BagError, OSError, ValueError) as error:
                self._skip(name, f"cannot take type {types[0]}: {error}")
                continue
            self._summary.counts[name] = 0
            self._summary.types[name] = types[0]
            self.create_subscription(
                cls, name, self._callback(name), subscription_qos(publishers), raw=True
            )
            self.get_logger().info(f"{self._verb} {name} ({types[0]})")

    def _skip(self, name: str, why: str) -> None:
        self._summary.skipped[name] = why
        self.get_logger().warning(f"not {self._verb} {name}: {why}")

    def _callback(self, topic: str) -> Callable[[bytes], None]:
        counts = self._summary.counts
        write = self._sink.write
        clock = self.get_clock()

        def on_message(data: bytes) -> None:
            write(topic, data, clock.now().nanoseconds)
            counts[topic] += 1

        return on_message


def record(
    options: RecordingOptions,
    args: Sequence[str] | None = None,
    on_ready: Callable[[], None] | None = None,
) -> RecordingSummary:
    """Record until Ctrl-C, SIGTERM or ``options.duration_s``; the bag is closed in every case
    (:func:`forward`). Raises ``BagError`` if the bag cannot be created (e.g. the output
    directory exists)."""
    writer = BagWriter(
        options.output,
        compression=options.compression,
        chunk_size=options.chunk_size,
        max_file_size=options.max_file_size,
        max_file_duration_ns=int(options.max_file_duration_s * 1e9),
    )
    summary = RecordingSummary(output=options.output)
    forward(writer, options, summary, ("feeder_recorder", "recording"), args, on_ready)
    summary.files = writer.files
    return summary


def forward(
    sink: TopicSink,
    options: TopicSelection,
    summary: Forwarded,
    name_and_verb: tuple[str, str],
    args: Sequence[str] | None = None,
    on_ready: Callable[[], None] | None = None,
) -> None:
    """Hand the selected topics to ``sink`` until Ctrl-C, SIGTERM or ``options.duration_s``
    (``name_and_verb``: the forwarding node's name and the verb of its log lines). ``sink`` is
    closed in every case, before the middleware's teardown (a teardown that hangs
    ends the process after ``runner.TEARDOWN_LIMIT_S`` with status 1, the sink closed)."""
    try:
        with RosSession(args=list(args) if args is not None else None) as init:
            context = init.context
            try:
                node = TopicRecorder(sink, options, summary, *name_and_verb)
            except Exception:
                if context.ok():
                    raise
                summary.stopped_by = "signal"  # a Ctrl-C (rclpy shut the context down) came first
                return
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            if on_ready is not None:
                on_ready()
            end = None if options.duration_s is None else time.monotonic() + options.duration_s
            summary.stopped_by = "shutdown"
            guard = StopOnShutdown(context)
            try:
                with guard:
                    while context.ok():
                        if end is not None and time.monotonic() >= end:
                            summary.stopped_by = f"--duration {options.duration_s:g} s"
                            break
                        executor.spin_once(timeout_sec=0.05)
                    else:
                        summary.stopped_by = "signal"
                if guard.stopped:
                    summary.stopped_by = "signal"
            finally:
                executor.remove_node(node)
                try:
                    # no callback writes once the loop has stopped: the sink is complete before
                    # the middleware's teardown, which the watchdog bounds (a Fast DDS teardown
                    # once spun for good; see runner.TEARDOWN_LIMIT_S)
                    sink.close()
                finally:
                    faulthandler.dump_traceback_later(runner.TEARDOWN_LIMIT_S, exit=True)
                    node.destroy_node()
    except (KeyboardInterrupt, ExternalShutdownException):
        summary.stopped_by = "signal"
    finally:
        faulthandler.cancel_dump_traceback_later()
        sink.close()
