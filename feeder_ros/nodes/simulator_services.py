"""The platform simulator's services: ``~/reset`` and ``~/pick_part`` (``std_srvs/Trigger``),
``~/spawn_parts`` (``feeder_ros/SpawnParts``).

``reset`` starts the simulation over at t = 0 with the configured parts; ``spawn_parts`` puts
parts at rest on the track, or refuses the request naming the offending value
(:func:`spawn_refusal`, ROS-free); ``pick_part`` takes the first part queued at a stopper
(``track_end:=stopper``), or says why there is none. :class:`SimulatorServices` is a mixin of
:class:`~feeder_ros.nodes.platform_simulator.PlatformSimulator`, which owns the simulation, its
lock and the queue at the stopper.
"""

from __future__ import annotations

import math
import threading
from typing import TYPE_CHECKING, Any

from std_srvs.srv import Trigger

from feeder_ros.physics.simulation import FeederSimulator, PartSpec
from feeder_ros.physics.track_end import TrackEndQueue
from feeder_ros.srv import SpawnParts

if TYPE_CHECKING:
    from rclpy.node import Node

    _Node = Node
else:
    _Node = object  # at run time the node class that mixes this in is the Node

MAX_SPAWN = 10000  #: parts one spawn_parts request may add


def spawn_refusal(
    count: int, position_m: float, spacing_m: float, end_m: float, end_name: str
) -> str:
    """Why ``count`` parts from ``position_m`` spaced ``spacing_m`` cannot be spawned on a track
    that ends at ``end_m`` (``end_name`` says what that end is), or "" if they can."""
    problems = []
    if count < 1 or count > MAX_SPAWN:
        problems.append(f"count={count} must be in 1..{MAX_SPAWN}")
    for name, value in (("position_m", position_m), ("spacing_m", spacing_m)):
        if not math.isfinite(value) or value < 0.0:
            problems.append(f"{name}={value!r} must be a finite value >= 0")
    if not problems and position_m + (count - 1) * spacing_m >= end_m:
        problems.append(
            f"parts from {position_m} m spaced {spacing_m} m do not fit on the track "
            f"({end_name}: {end_m:g} m)"
        )
    return "; ".join(problems)


class SimulatorServices(_Node):
    """The services' callbacks, registered by :meth:`_create_services` (on the node's state)."""

    _lock: threading.Lock
    _sim: FeederSimulator
    _queue: TrackEndQueue | None
    _values: dict[str, Any]

    if TYPE_CHECKING:

        def _start(self) -> None: ...

    def _create_services(self) -> None:
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SpawnParts, "~/spawn_parts", self._on_spawn)
        self.create_service(Trigger, "~/pick_part", self._on_pick)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        with self._lock:
            self._start()
        response.success = True
        response.message = f"reset to t = 0 with {self._sim.part_count} parts"
        return response

    def _on_spawn(self, request: SpawnParts.Request, response: SpawnParts.Response) -> Any:
        end_m, end_name = self._values["track_length_m"], "track_length_m"
        if self._queue is not None:
            end_m, end_name = self._queue.tail_m, "the tail of the queue at the stopper"
        refusal = spawn_refusal(
            request.count, request.position_m, request.spacing_m, end_m, end_name
        )
        if refusal:
            response.success = False
            response.message = refusal
            return response
        with self._lock:
            ids = [
                self._sim.spawn_part(
                    PartSpec(position_m=request.position_m + i * request.spacing_m), at_rest=True
                )
                for i in range(request.count)
            ]
        response.success = True
        response.part_ids = ids
        response.message = f"spawned {len(ids)} parts"
        return response

    def _on_pick(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        with self._lock:
            response.success, response.message = (
                (False, "track_end is open: parts leave at the end of the track")
                if self._queue is None
                else self._queue.answer_pick(self._sim.time_s)
            )
        return response
