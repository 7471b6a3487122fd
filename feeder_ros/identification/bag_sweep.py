"""The bag source: a sweep recorded in rosbag2 (MCAP) bags, read back as sweep points.

Each bag goes through :func:`feeder_ros.bag.analysis.analyze_bag` (what ``feeder analyze`` does):
it cuts the recording into segments of constant drive setting, leaves out the short ones (ramps) as
transient, and gives each segment's mean part speed from the best source the bag has (ground truth
``parts/state``, else part-sensor transits, else the sensorless estimator). Every steady, driven
segment becomes one :class:`~feeder_ros.identification.sweep.SweepPoint`:

* frequency and force amplitude are the drive actually applied (``CarrierState``, else
  ``DriveCommand``); the amplitude in % is ``amplitude_n / full_scale_force_n * 100``;
* the part mass is not in the bag: the caller gives it (one for all bags or one per bag);
* the speed is the segment's mean as ``feeder analyze`` reports it, over the whole segment: the
  settling at the start of a segment is inside it (a sweep recorded with a settle time much
  shorter than its window, or a well damped feeder, keeps that bias small);
* a segment shorter than ``min_duration_s`` (e.g. the plan's window) or without any speed source is
  kept as a point that is not ok, with the reason.

A setting that appears in several segments gives several points (the fit averages them).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from feeder_ros.bag.analysis import BagAnalysis, Segment, analyze_bag
from feeder_ros.identification.sweep import SweepDataError, SweepPoint, SweepResult

__all__ = ["BagSweep", "segment_point", "sweep_from_bags"]

Progress = Callable[[int, float], None]  # (bag index, fraction of that bag read)


@dataclass(frozen=True)
class BagSweep:
    """The points of all bags and, per bag, its analysis (segments, problems)."""

    result: SweepResult
    analyses: tuple[BagAnalysis, ...]

    def speed_sources(self) -> dict[str, int]:
        """How many points took their speed from each source."""
        counts: dict[str, int] = {}
        for analysis in self.analyses:
            for segment in analysis.segments:
                if segment.enabled:
                    name = _speed_source(segment)
                    counts[name] = counts.get(name, 0) + 1
        return counts


def _speed_source(segment: Segment) -> str:
    if not math.isnan(segment.speed_ground_truth_mps):
        return "ground truth"
    if not math.isnan(segment.speed_sensors_mps):
        return "sensor transits"
    if not math.isnan(segment.speed_estimate_mps):
        return "estimator"
    return "none"


def segment_point(
    segment: Segment, full_scale_force_n: float, part_mass_kg: float, min_duration_s: float
) -> SweepPoint | None:
    """The sweep point of one analysed segment; ``None`` for a segment without drive (off, or
    before the first drive information)."""
    if not segment.enabled or segment.frequency_hz is None or segment.amplitude_n is None:
        return None
    speed = segment.speed_mps
    reason = ""
    if segment.duration_s < min_duration_s:
        reason = (
            f"segment of {segment.duration_s:.3g} s at {segment.start_s:.3f} s is shorter than "
            f"{min_duration_s:g} s"
        )
    elif math.isnan(speed):
        reason = "no part speed in the bag for this segment (no parts/state, transits, estimate)"
    return SweepPoint(
        frequency_hz=float(segment.frequency_hz),
        amplitude_percent=float(segment.amplitude_n) / full_scale_force_n * 100.0,
        amplitude_n=float(segment.amplitude_n),
        part_mass_kg=part_mass_kg,
        speed_mps=speed,
        duration_s=segment.duration_s,
        slip_fraction=segment.slip_fraction,
        ok=not reason,
        reason=reason,
    )


def sweep_from_bags(
    paths: Sequence[str | os.PathLike[str]],
    *,
    full_scale_force_n: float,
    part_masses_kg: Sequence[float],
    min_duration_s: float = 0.5,
    min_segment_s: float = 0.5,
    namespace: str | None = None,
    progress: Progress | None = None,
) -> BagSweep:
    """Sweep points from recorded bags (see the module docstring).

    ``part_masses_kg``: one mass for every bag, or one per bag. ``min_segment_s`` is the analysis'
    transient limit (ramp steps are shorter); ``min_duration_s`` the shortest segment that counts
    as a measurement; ``namespace`` picks the feeder of bags that hold several. Raises
    :class:`SweepDataError` (or the bag reader's ``BagError``) when a bag cannot be analysed or
    holds no driven segment."""
    if not paths:
        raise SweepDataError("no bags given")
    if not (math.isfinite(full_scale_force_n) and full_scale_force_n > 0.0):
        raise SweepDataError(f"full_scale_force_n={full_scale_force_n!r} must be > 0")
    masses = list(part_masses_kg)
    if len(masses) == 1:
        masses = masses * len(paths)
    if len(masses) != len(paths):
        raise SweepDataError(
            f"{len(part_masses_kg)} part masses for {len(paths)} bags: give one mass for all "
            "bags or one per bag"
        )
    points: list[SweepPoint] = []
    analyses: list[BagAnalysis] = []
    for k, (path, mass) in enumerate(zip(paths, masses, strict=True)):
        report = None if progress is None else (lambda f, k=k: progress(k, f))
        analysis = analyze_bag(
            path, min_segment_s=min_segment_s, namespace=namespace, progress=report
        )
        found = [
            p
            for p in (
                segment_point(s, full_scale_force_n, mass, min_duration_s)
                for s in analysis.segments
            )
            if p is not None
        ]
        if not found:
            raise SweepDataError(
                f"{Path(path)}: no driven segment of at least {min_segment_s:g} s "
                f"(drive source: {analysis.drive_source}; {len(analysis.segments)} segments)"
            )
        points.extend(found)
        analyses.append(analysis)
    names = ", ".join(Path(p).name for p in paths)
    return BagSweep(SweepResult(tuple(points), f"bag {names}", full_scale_force_n), tuple(analyses))
