"""Part transits between two part-present sensors: the paper's 8.5 cm timing (ROS-free).

A part that covers the first sensor and later the second one has moved the sensors' distance in
the time between the two rising edges. Parts do not overtake on a track, so without part ids the
rising edges pair first in, first out; with ids (the simulator's) they pair by id.

:meth:`TransitTimer.on_edge` takes each edge with its own stamp (delivery delays do not distort a
transit) and returns the :class:`Transit` a second-sensor edge completes. Refused, with the reason
(:attr:`TransitTimer.last_refusal`): a transit whose time is not positive, or that is faster than
``max_speed_mps`` (no carrier carries a part that fast: a bounced edge, a sensor wired to the wrong
input).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = ["Transit", "TransitTimer"]

#: arrivals at the first sensor remembered without a matching second edge (a part taken off the
#: track between the sensors leaves one behind; the oldest go first)
MAX_PENDING = 64


@dataclass(frozen=True)
class Transit:
    start_s: float  #: rising edge at the first sensor
    end_s: float  #: rising edge at the second sensor
    distance_m: float
    part_id: int | None

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    @property
    def speed_mps(self) -> float:
        return self.distance_m / self.duration_s


class TransitTimer:
    """Pairs rising edges of sensor ``first`` and sensor ``second`` ``distance_m`` apart."""

    def __init__(
        self, first: int, second: int, distance_m: float, max_speed_mps: float = math.inf
    ) -> None:
        if first == second:
            raise ParameterError(f"the transit sensors must differ, got {first} and {second}")
        if not (is_number(distance_m) and math.isfinite(distance_m) and distance_m > 0.0):
            raise ParameterError(f"transit distance_m={distance_m!r} must be finite and > 0")
        if not (is_number(max_speed_mps) and max_speed_mps > 0.0):
            raise ParameterError(f"max_speed_mps={max_speed_mps!r} must be > 0")
        self.first, self.second = int(first), int(second)
        self.distance_m = float(distance_m)
        self.max_speed_mps = float(max_speed_mps)
        self.last_refusal = ""
        self.reset()

    def reset(self) -> None:
        self._by_part: dict[int, float] = {}
        self._queue: deque[float] = deque(maxlen=MAX_PENDING)

    def on_edge(
        self, stamp_s: float, sensor: int, part: int | None, present: bool
    ) -> Transit | None:
        """An edge of ``sensor`` at ``stamp_s`` (``part``: its id where known); the transit a rising
        edge at the second sensor completes, if any."""
        if not present or not math.isfinite(stamp_s):
            return None
        if sensor == self.first:
            if part is None:
                self._queue.append(stamp_s)
            else:
                if len(self._by_part) >= MAX_PENDING:
                    self._by_part.pop(next(iter(self._by_part)))
                self._by_part[part] = stamp_s
            return None
        if sensor != self.second:
            return None
        if part is not None:
            start = self._by_part.pop(part, math.nan)
        else:
            start = self._queue.popleft() if self._queue else math.nan
        if not math.isfinite(start):
            return None
        transit = Transit(start, stamp_s, self.distance_m, part)
        if transit.duration_s <= 0.0:
            self.last_refusal = (
                f"transit of part {part} took {transit.duration_s:.6g} s (edges at {start:.6f} "
                f"and {stamp_s:.6f} s): not positive"
            )
            return None
        if transit.speed_mps > self.max_speed_mps:
            self.last_refusal = (
                f"transit of part {part} at {transit.speed_mps:.6g} m/s ({transit.duration_s:.6g} "
                f"s over {self.distance_m:g} m) is faster than the carrier can carry a part "
                f"({self.max_speed_mps:.6g} m/s)"
            )
            return None
        return transit
