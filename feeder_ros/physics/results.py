"""What a simulation returns: part phases and event kinds, part specifications, the event log
and the results of a run (:class:`SimulationResult`) and of a batch (:class:`ManySummary`).

Plain records (no solver): :mod:`feeder_ros.physics.simulation` and
:mod:`feeder_ros.physics.smooth_model` build them.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.exact import layout, ordering, sampling
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.parameters import finite_number as _finite

__all__ = [
    "EventArrays",
    "EventKind",
    "EventLog",
    "ManySummary",
    "PartSpec",
    "Phase",
    "SimulationResult",
]

F64 = npt.NDArray[np.float64]
I8 = npt.NDArray[np.int8]
I64 = npt.NDArray[np.int64]


class Phase(enum.IntEnum):
    """Contact phase of a part (``part_phase`` codes)."""

    EXITED = -1  #: left the track (column frozen at nan)
    STICK = 0
    SLIP_FORWARD = 1  #: the part slides forward over the carrier (u > x')
    SLIP_BACKWARD = 2  #: the part lags behind the carrier (u < x')


class EventKind(enum.IntEnum):
    """Kinds of located events (``event_kind`` codes)."""

    BRANCH_SWITCH = layout.EV_BRANCH  #: stiffness branch changes (carrier)
    SLIP_START = layout.EV_SLIP_START  #: a sticking part starts to slip
    STICK = layout.EV_STICK  #: relative velocity zero and the part sticks again
    SLIP_REVERSAL = layout.EV_REVERSAL  #: relative velocity zero, the part slips the other way
    DRIVE_CHANGE = layout.EV_DRIVE  #: a drive change (first step of a ramp) takes effect
    PART_EXIT = layout.EV_EXIT  #: a part passes the track end
    SLIDING_START = layout.EV_SLIDE_START  #: velocity switching: carrier held at x' = 0 (Filippov)
    SLIDING_END = layout.EV_SLIDE_END  #: velocity switching: carrier released


@dataclass(frozen=True)
class PartSpec:
    """One part: track position where it is put down, mass and friction (``None``: from the
    params)."""

    position_m: float = 0.0
    mass_kg: float | None = None
    static_friction: float | None = None
    kinetic_friction: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", _finite("position_m", self.position_m))
        for name in ("mass_kg", "static_friction", "kinetic_friction"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _finite(name, value, positive=True))
        if (
            self.static_friction is not None
            and self.kinetic_friction is not None
            and self.kinetic_friction > self.static_friction
        ):
            raise ParameterError(
                f"kinetic_friction={self.kinetic_friction!r} must not exceed "
                f"static_friction={self.static_friction!r}"
            )

    def resolved(self, params: FeederParameters) -> tuple[float, float, float]:
        """(mass_kg, static_friction, kinetic_friction) with ``None`` replaced from ``params``."""
        mass = params.part_mass_kg if self.mass_kg is None else self.mass_kg
        mu_s = params.static_friction if self.static_friction is None else self.static_friction
        mu_d = params.kinetic_friction if self.kinetic_friction is None else self.kinetic_friction
        if mu_d > mu_s:
            raise ParameterError(
                f"part kinetic_friction={mu_d!r} must not exceed static_friction={mu_s!r}"
            )
        return mass, mu_s, mu_d


EventArrays = tuple[F64, I8, I64]


class EventLog:
    """A run's events in time order, ``(t_s, kind, part)``, put in order when first read.

    The group march leaves its events per group of parts; putting 600,000 of them (1000 parts,
    10 s at 40 N) into one time-ordered list takes about a seventh of that run, so a run whose
    events are never read does not pay for it. ``EventLog.of(t, kind, part)`` wraps arrays that
    are already in time order. Pickles as its ordered arrays.
    """

    __slots__ = ("_arrays", "_chunks")

    def __init__(self, chunks: Sequence[EventArrays | Callable[[], EventArrays]]) -> None:
        """``chunks``: event arrays, or functions that return them, to be concatenated in this
        order and then sorted stably by time (a chunk of the group march is in order already)."""
        self._chunks: tuple[EventArrays | Callable[[], EventArrays], ...] = tuple(chunks)
        self._arrays: EventArrays | None = None

    @classmethod
    def of(cls, t_s: npt.ArrayLike, kind: npt.ArrayLike, part: npt.ArrayLike) -> EventLog:
        """Events already in time order (``t_s`` float64, ``kind`` int8, ``part`` int64)."""
        log = cls(())
        log._arrays = (
            np.asarray(t_s, dtype=np.float64),
            np.asarray(kind, dtype=np.int8),
            np.asarray(part, dtype=np.int64),
        )
        return log

    def arrays(self) -> EventArrays:
        """``(t_s, kind, part)`` in time order (built on the first call, then kept)."""
        if self._arrays is None:
            chunks = [chunk() if callable(chunk) else chunk for chunk in self._chunks]
            self._arrays = _in_time_order(chunks)
            self._chunks = ()
        return self._arrays

    def __reduce__(self) -> tuple[Callable[..., EventLog], EventArrays]:
        return (EventLog.of, self.arrays())


def _in_time_order(chunks: list[EventArrays]) -> EventArrays:
    """The chunks' events, one after the other, sorted stably by time."""
    if not chunks:
        return np.zeros(0), np.zeros(0, np.int8), np.zeros(0, np.int64)
    if len(chunks) == 1 and sampling.check_samples(chunks[0][0]) == 0:
        # one chunk (fresh copies) already in time order: as it is
        t, kind, part = chunks[0]
        return t, kind.astype(np.int8, copy=False), part.astype(np.int64, copy=False)
    event_t = np.concatenate([c[0] for c in chunks])
    event_kind = np.concatenate([c[1] for c in chunks]).astype(np.int8, copy=False)
    event_part = np.concatenate([c[2] for c in chunks]).astype(np.int64, copy=False)
    if sampling.check_samples(event_t) != 0:
        # out of order (a drive change at the chunk's end comes first) or not finite; the group
        # march's passes come in order one after the other and need no sort
        order = ordering.stable_time_order(event_t)
        event_t = event_t[order]
        event_kind = event_kind[order]
        event_part = event_part[order]
    return event_t, event_kind, event_part


@dataclass(frozen=True)
class SimulationResult:
    """Samples and events of a run (or of one ``FeederSimulator.advance`` chunk).

    Sample arrays: ``t_s`` (n,); carrier ``carrier_x_m``, ``carrier_v_mps``, ``carrier_a_mps2``
    (n,),
    ``branch`` (n,) int8 (+1 forward K_f, -1 backward K_b, 0 held by velocity switching);
    parts ``part_x_m``, ``part_v_mps`` (n, N) lab frame, ``part_phase`` (n, N) int8
    (:class:`Phase`).
    Events, time-ordered: ``event_t_s``, ``event_kind`` (:class:`EventKind`), ``event_part`` (part
    index, -1 for carrier/drive events), from ``events`` (an :class:`EventLog`: put in time order
    when first read). Exact per-part totals over the run: ``part_start_t_s``,
    ``part_start_x_m`` (lab), ``part_end_t_s`` (exit time or end of run), ``part_end_x_m``,
    ``part_slip_time_s`` (time spent slipping) and ``part_exit_t_s`` (nan if still on the track).
    The (n, N) part arrays may be column-major (Fortran order) when the groups ran in parallel.
    """

    t_s: F64
    carrier_x_m: F64
    carrier_v_mps: F64
    carrier_a_mps2: F64
    branch: I8
    part_x_m: F64
    part_v_mps: F64
    part_phase: I8
    events: EventLog
    part_start_t_s: F64
    part_start_x_m: F64
    part_end_t_s: F64
    part_end_x_m: F64
    part_slip_time_s: F64
    part_exit_t_s: F64

    @property
    def event_t_s(self) -> F64:
        return self.events.arrays()[0]

    @property
    def event_kind(self) -> I8:
        return self.events.arrays()[1]

    @property
    def event_part(self) -> I64:
        return self.events.arrays()[2]

    @property
    def part_count(self) -> int:
        return int(self.part_start_t_s.shape[0])

    def mean_part_speed_mps(self) -> F64:
        """Mean lab-frame speed of each part (N,): displacement over time on the track (exact)."""
        span = self.part_end_t_s - self.part_start_t_s
        with np.errstate(invalid="ignore", divide="ignore"):
            out = (self.part_end_x_m - self.part_start_x_m) / span
        return np.asarray(np.where(span > 0.0, out, np.nan), dtype=np.float64)

    def slip_fraction(self) -> F64:
        """Fraction of its time on the track that each part spent slipping (N,) (exact)."""
        span = self.part_end_t_s - self.part_start_t_s
        with np.errstate(invalid="ignore", divide="ignore"):
            out = self.part_slip_time_s / span
        return np.asarray(np.where(span > 0.0, out, np.nan), dtype=np.float64)

    def exited_count(self) -> int:
        """Number of parts that left the track (the feed count)."""
        return int(np.count_nonzero(np.isfinite(self.part_exit_t_s)))


@dataclass(frozen=True)
class ManySummary:
    """Summaries of :func:`simulate_many`, one entry per operating point (one part each)."""

    mean_part_speed_mps: F64
    slip_fraction: F64
    exit_t_s: F64  #: nan when the part stayed on the track
