"""A stopper at the end of the track, where parts queue until a robot picks them (ROS-free).

The platform simulator's ``track_end:=stopper`` (``open``, the default, lets parts leave at
``track_length_m``). :class:`TrackEndQueue` keeps the queue's bookkeeping; the node calls it around
each chunk it asks of the physics core (:class:`~feeder_ros.physics.simulation.FeederSimulator`).

Model:

* **Geometry.** A part's track position is its front; it covers ``[x - L, x]`` with ``L`` the
  part length (``part_length_m``, as the part-present sensors see it). The stopper stands at the
  track length ``T``. Queued parts stand in a row, touching: slot ``k`` (0: the front part,
  touching the stopper) has its front at ``T - k*L``. The queue's *tail*, ``T - n*L`` with ``n``
  parts queued, is where the next part stops. A new track length moves the stopper, and the queue
  with it (:meth:`TrackEndQueue.set_track_length`); the node reads the part length at start and
  on reset, as its sensors do.
* **Joining (exact).** The physics core is given the tail as its track length
  (:attr:`TrackEndQueue.core_track_length_m`), so its exact ``PART_EXIT`` event fires where a
  part meets the queue: with the stopper that event means "joined the queue", not "left the
  feeder". A queued part is out of the stick-slip physics: it sits still at its slot in the
  carrier frame (it moves with the carrier: relative velocity 0, phase STICK) and is not
  simulated any more. With ``coupling=two_way`` its mass then no longer loads the carrier, as if
  it had left the track (``one_way``, the default, counts one part's mass whatever the load).
* **Several joins in one chunk.** The core's track end moves to the new tail only when the chunk
  is over (:meth:`TrackEndQueue.settle`). So the first part to join in a chunk joins at its exact
  event; a later one in the same chunk (a part less than one part length, plus the chunk's
  travel, behind) joins where its samples cross its own slot (linear interpolation between
  samples, and never earlier than the join before it), and a part found past the new tail at the
  chunk's end (the node samples the chunk's end) joins likewise; the core lets it go at the start
  of the next chunk. Either way, once the part ahead of it has joined, a part is never shown
  past its slot. Parts are points to the physics (nothing keeps two moving parts a part length
  apart): a part already past the tail when the part ahead of it joins is set back to its slot at
  once; parts put down on top of each other (spawned together with no spacing) queue one per
  slot, past the track's start if need be.
* **Picking.** A pick takes the front part off the track at once (it leaves the feeder: the
  node publishes it on ``parts/exit``) and the remaining parts move up one slot *at once*, a
  simplification: a real row slides forward in a fraction of a second. The tail moves forward by
  a part length, and the core's track length with it. A pick asked for is carried out at the
  start of the node's next chunk, at the simulation time it was asked for (nothing has been
  simulated in between).
* **Full track.** When the tail has reached the feed position (``tail <= part_start_m``) a part
  put down there would stand in the queue: the node skips such a feed and counts it
  (:meth:`TrackEndQueue.is_full`). The core's track length stays positive (a full track with
  ``part_start_m`` near 0 can push the tail to or below 0: the core then gets
  :data:`MIN_CORE_TRACK_M`).
* **The bowl's exit.** Open track end or stopper, a bowl cannot put a part onto an occupied
  track start (a track that does not move would get parts on top of each other): a feed is
  skipped while a part still on the track would overlap the new one (:func:`start_blocked`: a
  front within a part length of ``part_start_m``; touching is no overlap; with ``part_length_m``
  0, parts as points, only a part at the feed position itself, to :data:`COINCIDENT_M`). The node
  counts such skips (``feeds_skipped_start_blocked``) apart from those on a full track
  (``feeds_skipped_track_full``), and feeds again at the next feed interval. It checks the parts
  still in the physics core: queued parts never block a track that is not full (the last one's
  rear is the tail, past the feed position).
* **Sensors.** Queued parts are written into the sampled track positions at their slots
  (:meth:`TrackEndQueue.overlay`) before the part-present sensors see them: a sensor under the
  queue gets its rising edge when a part arrives over it and no edge while the part sits there. At
  a pick the parts jump: :func:`pick_edges` gives the sensors the instant twice (before and after
  the jump, at the pick time), a picked part leaving the sensors it covered, and keeps only what
  a light barrier shows: the falling edge where a sensor becomes free, the rising edge where one
  becomes covered, nothing where one part moves off a sensor as the next moves on.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.parameters import ParameterError, finite_number

__all__ = [
    "COINCIDENT_M",
    "MIN_CORE_TRACK_M",
    "Join",
    "Picks",
    "TrackEndQueue",
    "covered_sensors",
    "pick_edges",
    "start_blocked",
]

F64 = npt.NDArray[np.float64]
#: the physics core's track length when the queue's tail is at or below the track's start
MIN_CORE_TRACK_M = 1e-9
#: round-off of track positions: parts touching to this do not overlap; parts of length 0 (points)
#: overlap only at the same position, to this
COINCIDENT_M = 1e-9


@dataclass(frozen=True)
class Join:
    """A part joined the queue at ``t_s`` and stopped with its front at ``slot_m``."""

    part: int
    t_s: float
    slot_m: float


@dataclass(frozen=True)
class Picks:
    """Parts picked at the start of a chunk, and every queued part's slot just before."""

    parts: tuple[int, ...] = ()
    before_m: Mapping[int, float] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.parts)


class TrackEndQueue:
    """The parts queued at the stopper, front first, with their slots and join times."""

    def __init__(self, track_length_m: float, part_length_m: float) -> None:
        self._track = finite_number("track_length_m", track_length_m, positive=True)
        self._length = finite_number("part_length_m", part_length_m, positive=True)
        self._parts: list[int] = []  # front first
        self._since: list[float] = []  # join times, in the same order
        self._pending = 0  # picks asked for, carried out at the next chunk's start
        # parts joined from the samples whose PART_EXIT the core has not given yet (queued or
        # already picked): the core still simulates them, their positions are not shown
        self._in_core: set[int] = set()
        self.picked_total = 0
        self.feeds_skipped = 0  # feeds refused by admit_feed: the track was full
        self.picks_missed = 0  # robot picks (periodic_pick) that found no part

    # -- state ---------------------------------------------------------------------------------
    @property
    def parts(self) -> tuple[int, ...]:
        """The queued parts, front (touching the stopper) first."""
        return tuple(self._parts)

    def __len__(self) -> int:
        return len(self._parts)

    def __contains__(self, part: object) -> bool:
        return part in self._parts

    @property
    def track_length_m(self) -> float:
        return self._track

    @property
    def part_length_m(self) -> float:
        return self._length

    def set_track_length(self, track_length_m: float) -> None:
        """Move the stopper; the queued parts move with it (each stays in its slot)."""
        self._track = finite_number("track_length_m", track_length_m, positive=True)

    def slot_m(self, index: int) -> float:
        """Track position of the front of slot ``index`` (0 touches the stopper)."""
        return self._track - index * self._length

    @property
    def tail_m(self) -> float:
        """Where the next part stops: the rear of the last queued part."""
        return self.slot_m(len(self._parts))

    @property
    def core_track_length_m(self) -> float:
        """The physics core's track length: the tail, kept positive."""
        return max(self.tail_m, MIN_CORE_TRACK_M)

    def is_full(self, start_m: float) -> bool:
        """Whether a part put down at ``start_m`` would stand in the queue (no room left)."""
        return self.tail_m <= start_m

    def admit_feed(self, start_m: float) -> bool:
        """Whether a part may be put down at ``start_m``; a refusal (full track) is counted."""
        if self.is_full(start_m):
            self.feeds_skipped += 1
            return False
        return True

    def slots(self) -> dict[int, float]:
        """``{part: front of its slot}`` of every queued part."""
        return {part: self.slot_m(k) for k, part in enumerate(self._parts)}

    def queued_at(self, t_s: float, count: int) -> npt.NDArray[np.bool_]:
        """(count,) mask of the parts that stood in the queue at ``t_s``."""
        mask = np.zeros(count, bool)
        for part, since in zip(self._parts, self._since, strict=True):
            if since <= t_s and part < count:
                mask[part] = True
        return mask

    def clear(self) -> None:
        """Empty the queue (a reset); picks asked for are dropped."""
        self._parts.clear()
        self._since.clear()
        self._pending = 0
        self._in_core.clear()
        self.picked_total = self.feeds_skipped = self.picks_missed = 0

    # -- joining -------------------------------------------------------------------------------
    def join(self, part: int, t_s: float) -> Join:
        """``part`` stops at the tail at ``t_s``; the tail moves back a part length."""
        if part in self._parts:
            raise ParameterError(f"part {part} is already queued")
        if self._since and t_s < self._since[-1]:
            raise ParameterError(
                f"part {part} joins at t = {t_s!r} s, before the last join ({self._since[-1]!r} s)"
            )
        join = Join(part, float(t_s), self.tail_m)
        self._parts.append(part)
        self._since.append(join.t_s)
        return join

    def settle(self, times: F64, track: F64, exit_t_s: F64, exit_part: npt.ArrayLike) -> list[Join]:
        """The joins of one chunk of the physics core, then :meth:`overlay` on ``track``.

        ``times`` (n,): the chunk's sample times, sorted, its end included (n may be 0);
        ``track`` (n, N): the core's track positions (nan after a part left the core), changed
        in place; ``exit_t_s``/``exit_part``: the chunk's ``PART_EXIT`` events in time order.
        During the chunk the core's track length was :attr:`core_track_length_m` as it is on
        entry. Call :attr:`core_track_length_m` afterwards for the core's next chunk.
        """
        core_end = self.core_track_length_m
        joins: list[Join] = []
        floor = self._since[-1] if self._since else -math.inf
        released = []  # parts joined from the samples that the core lets go in this chunk
        for t, part in zip(
            np.asarray(exit_t_s).tolist(), np.asarray(exit_part).tolist(), strict=True
        ):
            if part in self._in_core:  # joined from the samples before: the core lets it go now
                self._in_core.discard(part)
                released.append(part)
                continue
            slot = self.tail_m
            if slot >= core_end or track.shape[0] == 0:
                at = t  # met the queue at the core's exact event
            else:
                at = _crossing(times, track[:, part], slot, end=(t, core_end))
            joins.append(self.join(part, min(max(at, floor), t)))
            floor = joins[-1].t_s
        if times.size:
            last = track[-1].copy()  # the chunk's end
            last[self._parts + sorted(self._in_core)] = np.nan
            while True:
                past = np.flatnonzero(last > self.tail_m)  # nan compares False
                if past.size == 0:
                    break
                part = int(past[np.argmax(last[past])])  # the one furthest ahead first
                at = _crossing(times, track[:, part], self.tail_m, end=None)
                joins.append(self.join(part, min(max(at, floor), float(times[-1]))))
                self._in_core.add(part)
                floor = joins[-1].t_s
                last[part] = np.nan
        self.overlay(times, track)
        picked = [part for part in released if part not in self._parts]
        track[:, picked] = np.nan  # picked before the core let them go
        return joins

    def overlay(self, times: F64, track: F64) -> None:
        """Write the queued parts' slots into ``track`` (n, N) in place, from their join times on;
        parts picked while the core still simulated them become nan."""
        if self._parts and times.size:
            columns = np.array(self._parts, np.int64)
            slots = np.array([self.slot_m(k) for k in range(len(self._parts))])
            since = np.array(self._since)
            joined = times[:, None] >= since[None, :]
            track[:, columns] = np.where(joined, slots[None, :], track[:, columns])
        gone = sorted(self._in_core - set(self._parts))
        if gone:
            track[:, gone] = np.nan

    # -- picking -------------------------------------------------------------------------------
    @property
    def pending_picks(self) -> int:
        return self._pending

    def request_pick(self) -> int | None:
        """Ask for the front part (after those already asked for); ``None`` when there is none.
        The pick is carried out by the next :meth:`take_picks`."""
        if self._pending >= len(self._parts):
            return None
        self._pending += 1
        return self._parts[self._pending - 1]

    def periodic_pick(self) -> None:
        """The robot's pick on its own schedule: the front part, or a miss (counted)."""
        if self.request_pick() is None:
            self.picks_missed += 1

    def answer_pick(self, t_s: float) -> tuple[bool, str]:
        """A pick on request at ``t_s``: (success, what happened or why not)."""
        part = self.request_pick()
        if part is None:
            return False, (
                f"no part to pick at the stopper: {len(self)} queued, "
                f"{self._pending} of them being picked"
            )
        return True, f"picked part {part} at t = {t_s:.6f} s"

    def status(self) -> dict[str, str]:
        """Diagnostic values: the queue, picks, feeds refused."""
        return {
            "parts_queued": str(len(self)),
            "queue_tail_m": f"{self.tail_m:.6g}",
            "parts_picked_total": str(self.picked_total),
            "picks_missed_queue_empty": str(self.picks_missed),
            "feeds_skipped_track_full": str(self.feeds_skipped),
        }

    def take_picks(self) -> Picks:
        """Carry out the picks asked for: the front parts leave, the rest move up."""
        if self._pending == 0:
            return Picks()
        before = self.slots()
        picked = tuple(self._parts[: self._pending])
        del self._parts[: self._pending]
        del self._since[: self._pending]
        self.picked_total += self._pending
        self._pending = 0
        return Picks(picked, before)

    def before_picks(self, row: F64, picks: Picks) -> F64:
        """The pick instant's track row (N,) as it stood before ``picks`` (the core's row there,
        with the queue written in as it was)."""
        before = row.copy()
        before[sorted(self._in_core - set(picks.before_m))] = np.nan
        for part, slot in picks.before_m.items():
            before[part] = slot
        return before


def _crossing(times: F64, x: F64, level: float, end: tuple[float, float] | None) -> float:
    """When the samples ``x`` (at ``times``) first reach ``level``, interpolated linearly between
    the samples around it; ``end``: a point (t, x) after the last finite sample (the core's exit
    event), for a part whose samples stop short of ``level``."""
    reached = x >= level  # nan compares False
    if reached.any():
        row = int(np.argmax(reached))
        if row == 0 or not math.isfinite(x[row - 1]):
            return float(times[row])
        t0, x0, t1, x1 = float(times[row - 1]), float(x[row - 1]), float(times[row]), float(x[row])
    else:
        finite = np.flatnonzero(np.isfinite(x))
        if end is None or finite.size == 0:
            return float(times[-1]) if end is None else end[0]
        row = int(finite[-1])
        t0, x0 = float(times[row]), float(x[row])
        t1, x1 = end
    return t0 + (t1 - t0) * (level - x0) / (x1 - x0) if x1 != x0 else t1


def start_blocked(track_m: npt.ArrayLike, start_m: float, part_length_m: float) -> bool:
    """Whether a part put down at ``start_m`` would overlap a part on the track (the bowl's exit
    is blocked): a front in ``track_m`` (nan: no part) less than ``part_length_m`` from
    ``start_m``, ahead or behind. Touching parts (a part length apart to :data:`COINCIDENT_M`)
    do not overlap; parts of length 0 do when they stand at the same position (to it)."""
    fronts = np.asarray(track_m, dtype=np.float64)
    reach = max(float(part_length_m) - COINCIDENT_M, COINCIDENT_M)
    return bool(np.any(np.abs(fronts - start_m) < reach))  # nan compares False


def covered_sensors(positions_m: Sequence[float], part_length_m: float, track: F64) -> list[bool]:
    """Which sensors a light barrier reports covered with the parts' fronts at ``track`` (N,)
    (nan: no part): a part covers ``p`` while ``front - part_length_m < p <= front``."""
    fronts = track[np.isfinite(track)]
    return [bool(np.any((fronts >= p) & (fronts - part_length_m < p))) for p in positions_m]


class _Edge(Protocol):
    @property
    def sensor_index(self) -> int: ...

    @property
    def present(self) -> bool: ...


EdgeT = TypeVar("EdgeT", bound=_Edge)
EdgeT_co = TypeVar("EdgeT_co", bound=_Edge, covariant=True)


class _Sensors(Protocol[EdgeT_co]):
    @property
    def positions_m(self) -> Sequence[float]: ...

    @property
    def part_length_m(self) -> float: ...

    def update(self, t_s: F64, track_m: F64) -> Sequence[EdgeT_co]: ...


def pick_edges(
    sensors: _Sensors[EdgeT], times: F64, track: F64, before: F64, picks: Picks
) -> list[EdgeT]:
    """The sensors' edges over a chunk that began with ``picks``.

    ``track`` (n, N): the chunk's track positions with the queue written in as it is after the
    picks; ``before`` (N,): the first row (the pick instant) with the slots as they were before.
    The sensors see the pick instant twice, before and after the parts' jump, then the rest of the
    chunk; of the jump's edges only the changes a light barrier shows are kept (module docstring).
    Without picks: the sensors' edges over the chunk as they are.
    """
    if not picks:
        return list(sensors.update(times, track))
    edges = list(sensors.update(times[:1], before[None, :]))
    after = track[0].copy()
    for part in picks.parts:  # seen leaving the sensors it covered (its falling edges)
        after[part] = picks.before_m[part] + sensors.part_length_m
    was = covered_sensors(sensors.positions_m, sensors.part_length_m, before)
    now = covered_sensors(sensors.positions_m, sensors.part_length_m, track[0])
    jumps = sensors.update(times[:1], after[None, :])
    edges += [
        edge
        for edge in sorted(jumps, key=lambda edge: edge.present)  # falling first
        if was[edge.sensor_index] != now[edge.sensor_index]
        and edge.present == now[edge.sensor_index]
    ]
    return edges + list(sensors.update(times[1:], track[1:]))
