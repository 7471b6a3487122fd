"""The live sweep's meters (ROS-free): mean part speed over a window from what a running cell
publishes, fed by :mod:`feeder_ros.nodes.sweep_client` (thread-safe: its executor adds while the
sweep measures).

* :class:`TransitMeter`: part-present sensor edges, transits between two sensors;
* :class:`StatusMeter`: speed samples such as the speed monitor's estimated speed;
* :class:`TruthMeter`: snapshots of the parts' track positions (the simulator's ground truth).
"""

from __future__ import annotations

import itertools
import math
import threading
from collections import deque
from dataclasses import dataclass

__all__ = ["Measurement", "StatusMeter", "TransitMeter", "TruthMeter"]


@dataclass(frozen=True)
class Measurement:
    """Mean speed over ``duration_s`` from ``count`` samples/transits/parts; NaN when none."""

    speed_mps: float
    duration_s: float
    count: int
    covered_m: float = math.nan

    @property
    def ok(self) -> bool:
        return self.count > 0 and math.isfinite(self.speed_mps)


class TransitMeter:
    """Transits of parts between two part-present sensors (rising edges, stamps in seconds).

    Edges of one part are paired by its id; sensors that do not know the part
    (``part=None``) are paired first in, first out, as parts cannot overtake on a track."""

    def __init__(self, first_sensor: int = 0, second_sensor: int = 1) -> None:
        self.first_sensor = first_sensor
        self.second_sensor = second_sensor
        self.distance_m = math.nan
        self._arrivals: dict[int, tuple[float, float]] = {}  # part -> (t, position) at first
        self._anonymous: deque[tuple[float, float]] = deque()
        self.transits: list[tuple[float, float, float]] = []  # (t first, t second, distance)
        self.latest_s = -math.inf  # stamp of the newest edge seen
        self._lock = threading.Lock()

    def add(
        self, t_s: float, sensor: int, position_m: float, part: int | None, present: bool
    ) -> None:
        with self._lock:
            self.latest_s = max(self.latest_s, t_s)
            if not present:
                return
            if sensor == self.first_sensor:
                if part is None:
                    self._anonymous.append((t_s, position_m))
                else:
                    self._arrivals.setdefault(part, (t_s, position_m))
            elif sensor == self.second_sensor:
                if part is None:
                    start = self._anonymous.popleft() if self._anonymous else None
                else:
                    start = self._arrivals.pop(part, None)
                if start is None or t_s <= start[0]:
                    return
                distance = position_m - start[1]
                if distance > 0.0:
                    self.distance_m = distance
                    self.transits.append((start[0], t_s, distance))

    def measure(self, t0_s: float, t1_s: float) -> Measurement:
        """Transits that began at or after ``t0_s`` and ended by ``t1_s``: mean of their speeds
        (each distance over time); ``duration_s`` is their mean transit time."""
        with self._lock:
            inside = [(a, b, d) for a, b, d in self.transits if a >= t0_s and b <= t1_s]
        if not inside:
            return Measurement(math.nan, t1_s - t0_s, 0)
        speeds = [d / (b - a) for a, b, d in inside]
        durations = [b - a for a, b, _ in inside]
        return Measurement(
            sum(speeds) / len(speeds),
            sum(durations) / len(durations),
            len(inside),
            sum(d for _, _, d in inside) / len(inside),
        )

    def first_transit(self, t0_s: float) -> Measurement | None:
        """The first transit that began at or after ``t0_s`` (distance mode), if complete."""
        with self._lock:
            done = [(a, b, d) for a, b, d in self.transits if a >= t0_s]
        if not done:
            return None
        a, b, d = min(done, key=lambda transit: transit[1])
        return Measurement(d / (b - a), b - a, 1, d)


class StatusMeter:
    """Speed samples (stamp, speed) such as the speed monitor's estimated speed."""

    def __init__(self) -> None:
        self.samples: list[tuple[float, float]] = []
        self.latest_s = -math.inf  # stamp of the newest message seen
        self._lock = threading.Lock()

    def add(self, t_s: float, speed_mps: float) -> None:
        with self._lock:
            self.latest_s = max(self.latest_s, t_s)
            if math.isfinite(speed_mps):
                self.samples.append((t_s, speed_mps))

    def _inside(self, t0_s: float, t1_s: float) -> list[tuple[float, float]]:
        with self._lock:
            return [(t, v) for t, v in self.samples if t0_s <= t <= t1_s]

    def measure(self, t0_s: float, t1_s: float) -> Measurement:
        inside = self._inside(t0_s, t1_s)
        if not inside:
            return Measurement(math.nan, t1_s - t0_s, 0)
        return Measurement(sum(v for _, v in inside) / len(inside), t1_s - t0_s, len(inside))

    def covered(self, t0_s: float, t1_s: float) -> Measurement:
        """Distance integrated from ``t0_s`` (each sample holds until the next) up to the last
        sample by ``t1_s``; speed = distance / time."""
        inside = self._inside(t0_s, t1_s)
        if len(inside) < 2:
            return Measurement(math.nan, 0.0, 0, 0.0)
        distance = sum(v * (t2 - t1) for (t1, v), (t2, _) in itertools.pairwise(inside))
        span = inside[-1][0] - inside[0][0]
        return Measurement(distance / span if span > 0 else math.nan, span, len(inside), distance)


class TruthMeter:
    """Snapshots (stamp, {part: track position}) of the parts on the track (ground truth)."""

    def __init__(self) -> None:
        self.snapshots: list[tuple[float, dict[int, float]]] = []
        self.latest_s = -math.inf  # stamp of the newest snapshot
        self._lock = threading.Lock()

    def add(self, t_s: float, positions: dict[int, float]) -> None:
        with self._lock:
            self.latest_s = max(self.latest_s, t_s)
            self.snapshots.append((t_s, positions))

    def measure(self, t0_s: float, t1_s: float) -> Measurement:
        """Mean advance of the parts on the track in both the first snapshot at or after ``t0_s``
        and the last at or before ``t1_s``, over the time between them."""
        with self._lock:
            inside = [(t, p) for t, p in self.snapshots if t0_s <= t <= t1_s]
        if len(inside) < 2:
            return Measurement(math.nan, 0.0, 0)
        (ta, first), (tb, last) = inside[0], inside[-1]
        common = sorted(set(first) & set(last))
        if not common or tb <= ta:
            return Measurement(math.nan, tb - ta, 0)
        advance = sum(last[k] - first[k] for k in common) / len(common)
        return Measurement(advance / (tb - ta), tb - ta, len(common), advance)
