"""The drive interface's tracking readings (TrackingFeedback) on a stand-in node: no DDS."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

from builtin_interfaces.msg import Time as TimeMsg

from feeder_ros.msg import SpeedStatus, VehicleEstimate
from feeder_ros.nodes.drive_tracking_feedback import FEEDBACK_QOS, TrackingFeedback


class _Node:
    """What TrackingFeedback uses of a node, recording the calls; its clock reads ``now_s``."""

    def __init__(self, now_s: float) -> None:
        self.now_s = now_s
        self.subscriptions: list[tuple[Any, str, Any, Any]] = []
        self.destroyed: list[object] = []
        self.warnings: list[str] = []

    def create_subscription(self, kind: Any, topic: str, callback: Any, qos: Any) -> object:
        self.subscriptions.append((kind, topic, callback, qos))
        return (kind, topic)

    def destroy_subscription(self, subscription: object) -> None:
        self.destroyed.append(subscription)

    def get_clock(self) -> Any:
        return SimpleNamespace(now=lambda: SimpleNamespace(nanoseconds=int(self.now_s * 1e9)))

    def get_logger(self) -> Any:
        return SimpleNamespace(warning=lambda text, **_: self.warnings.append(text))


class _Tracked:
    def __init__(self) -> None:
        self.readings: list[tuple[float, float]] = []

    def feedback(self, t_s: float, speed_mps: float) -> None:
        self.readings.append((t_s, speed_mps))


def _feedback(kind: str, now_s: float = 100.0) -> tuple[_Node, _Tracked, dict[str, Any], Any]:
    node, tracked = _Node(now_s), _Tracked()
    speeds: list[float] = []
    values = {
        "tracking.feedback_type": kind,
        "tracking.feedback_topic": "estimate",
        "tracking.min_confidence": 0.5,
    }
    link = TrackingFeedback(node, tracked, values, speeds.append)  # type: ignore[arg-type]
    return node, tracked, values, (link, speeds)


def _stamp(t_s: float) -> TimeMsg:
    return TimeMsg(sec=int(t_s), nanosec=round((t_s - int(t_s)) * 1e9))


def test_an_estimate_reaches_the_tracker_only_with_enough_confidence() -> None:
    node, tracked, values, (link, speeds) = _feedback("vehicle_estimate")
    [(kind, topic, callback, qos)] = node.subscriptions
    assert (kind, topic, qos) == (VehicleEstimate, "estimate", FEEDBACK_QOS)
    sure = VehicleEstimate(mean_speed_mps=0.02, mean_speed_confidence=0.9)
    sure.header.stamp = _stamp(99.5)
    callback(sure)
    unsure = VehicleEstimate(mean_speed_mps=0.05, mean_speed_confidence=0.4)
    unsure.header.stamp = _stamp(99.6)
    callback(unsure)  # below min_confidence: no reading at all
    callback(VehicleEstimate(mean_speed_mps=0.03, mean_speed_confidence=math.nan))
    assert tracked.readings == [(99.5, 0.02)]
    assert speeds == [0.02]
    values["tracking.min_confidence"] = 0.3  # a parameter change acts on the next message
    callback(unsure)
    assert tracked.readings[-1] == (99.6, 0.05)
    link.close()
    link.close()  # twice: nothing more to destroy
    assert node.destroyed == [(VehicleEstimate, "estimate")]


def test_a_speed_status_reading_unstamped_or_from_the_future() -> None:
    node, tracked, _values, (_link, speeds) = _feedback("speed_status", now_s=100.0)
    [(kind, _topic, callback, _qos)] = node.subscriptions
    assert kind is SpeedStatus
    callback(SpeedStatus(estimated_speed_mps=0.01))  # stamp 0: read at the node's now
    assert tracked.readings == [(100.0, 0.01)]
    ahead = SpeedStatus(estimated_speed_mps=0.02)
    ahead.header.stamp = _stamp(200.0)  # another clock (wall time against sim time)
    callback(ahead)
    assert tracked.readings[-1] == (200.0, 0.02)  # the tracker ignores it (its own test) ...
    assert speeds == [0.01, 0.02]
    [warning] = node.warnings  # ... and the node says why, naming the topic and the offset
    assert warning.startswith("speed_status stamped 200.000 s, 100 s ahead of this node's clock")
    assert "use_sim_time" in warning
