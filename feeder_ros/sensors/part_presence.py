"""Part-present sensors (light barriers) at fixed track positions.

A sensor at position ``p`` sees a part while the part covers it: from when its front (track
position) reaches ``p`` until its rear (front - part_length) passes ``p``. A part oscillates on the
track while it slips back and forth; a real barrier is debounced, so each (part, sensor) pair gives
one rising edge, the first time the front reaches ``p``, and one falling edge, the first time the
rear passes it. Edge times are interpolated linearly between samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["PartSensorArray", "SensorEdge"]


@dataclass(frozen=True)
class SensorEdge:
    t_s: float
    sensor_index: int
    position_m: float
    part: int
    present: bool  # True: rising edge (part arrives); False: falling edge (part has passed)


class PartSensorArray:
    def __init__(self, positions_m: Sequence[float], part_length_m: float) -> None:
        self.positions_m = [float(p) for p in positions_m]
        self.part_length_m = float(part_length_m)
        # per (sensor, edge kind): parts that already produced that edge
        self._done: list[list[set[int]]] = [[set(), set()] for _ in self.positions_m]
        self._last_t: float | None = None
        self._last_track: npt.NDArray[np.float64] = np.zeros(0)

    def update(
        self, t_s: npt.NDArray[np.float64], track_m: npt.NDArray[np.float64]
    ) -> list[SensorEdge]:
        """Edges in the new samples ``t_s`` (n,) with part track positions ``track_m`` (n, N)."""
        if t_s.size == 0:
            return []
        times = t_s
        positions = track_m
        if self._last_t is not None and self._last_track.size:
            width = positions.shape[1]
            previous = np.full((1, width), np.nan)
            count = min(width, self._last_track.size)
            previous[0, :count] = self._last_track[:count]
            times = np.concatenate(([self._last_t], t_s))
            positions = np.vstack((previous, positions))
        edges: list[SensorEdge] = []
        for s, position in enumerate(self.positions_m):
            for kind, level in ((0, position), (1, position + self.part_length_m)):
                done = self._done[s][kind]
                reached = positions >= level  # NaN (part gone or not yet there) compares False
                for part in np.flatnonzero(reached.any(axis=0)):
                    if int(part) in done:
                        continue
                    row = int(np.argmax(reached[:, part]))
                    t = float(times[row])
                    if row > 0 and np.isfinite(positions[row - 1, part]):
                        x0, x1 = positions[row - 1, part], positions[row, part]
                        t0 = float(times[row - 1])
                        t = t0 + (t - t0) * float((level - x0) / (x1 - x0)) if x1 != x0 else t
                    done.add(int(part))
                    edges.append(SensorEdge(t, s, position, int(part), kind == 0))
        self._last_t = float(t_s[-1])
        self._last_track = np.array(track_m[-1], dtype=np.float64)
        edges.sort(key=lambda edge: edge.t_s)
        return edges
