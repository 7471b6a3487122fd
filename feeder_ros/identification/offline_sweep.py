"""The offline sweep source: every point of a :class:`SweepPlan` run by the exact physics core.

Each point is the plant's :class:`~feeder_ros.physics.parameters.FeederParameters` with the point's
drive (``drive_frequency_hz``, ``drive_amplitude_n`` = amplitude % of ``full_scale_force_n``) and
part mass, one part put down at rest at the start of the track, the drive constant from t = 0.
:func:`~feeder_ros.physics.simulation.simulate_many` solves the points in parallel on all cores and
measures the part's exact mean speed over ``[settle_s, settle_s + window]``.

Choices, and why:

* **Part mass.** With one-way coupling the part's mass enters the carrier's equivalent mass
  ``M_eq = M + M_p + alpha*m`` (Eq. 2) and its own motion not at all (Coulomb friction scales with
  its weight); with two-way coupling it also sets the friction reaction on the carrier (Eq. 14).
  The point's mass is therefore set as the plant's ``part_mass_kg`` (``PartSpec.mass_kg`` is left
  ``None``, so the part takes the same mass from the point's parameters): both effects follow,
  and every point still runs in the one parallel call.
* **Endless track.** The sweep measures conveying speed, not the track: points run with
  ``track_length_m`` = :data:`ENDLESS_TRACK_M`, so no part leaves during a long window.
* **Distance instead of a window** (the paper timed parts over 8.5 cm): a first parallel pass
  measures a rough speed over :data:`PROBE_WINDOW_S` after the settle time, which brackets the
  time the part needs for the distance; bisection on the exact travel (``mean speed * window``,
  one exact run per trial window, as windows differ between points) then finds that time to
  :data:`TRAVEL_TOLERANCE_S`. A part advances in bursts (slip) with stands between them (stick),
  so ``distance / rough speed`` alone would be off by up to a burst. The reported ``duration_s``
  is that time and the speed ``distance / duration_s`` (exact for the window). A point whose
  part does not move forward, or would need more than ``max_window_s``, is measured over
  ``max_window_s`` and marked not ok with the reason (the paper kept only moving parts).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from feeder_ros.identification.sweep import SweepPlan, SweepPoint, SweepResult
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import PartSpec, simulate_many

__all__ = ["ENDLESS_TRACK_M", "PROBE_WINDOW_S", "offline_points", "offline_sweep"]

#: track length of the offline points: no part reaches its end within any window
ENDLESS_TRACK_M = 1.0e6
#: distance mode: the window of the rough-speed pass (or max_window_s if shorter)
PROBE_WINDOW_S = 1.0
#: distance mode: the time to travel the distance is found to this (bisection)
TRAVEL_TOLERANCE_S = 1e-4
#: points per parallel call (progress is reported between calls)
CHUNK_POINTS = 256

Progress = Callable[[int, int], None]  # (points done, points in all)


def offline_points(
    params: FeederParameters, plan: SweepPlan
) -> list[tuple[float, float, float, FeederParameters]]:
    """(mass kg, amplitude %, frequency Hz, parameters) of every point, in the plan's order."""
    if params.stiffness_model != "sharp":
        raise ValueError(
            f"stiffness_model={params.stiffness_model!r}: the offline sweep runs the exact "
            "(sharp) model; use --set stiffness_model=sharp"
        )
    base = params.with_changes(track_length_m=ENDLESS_TRACK_M)
    return [
        (
            mass,
            amplitude,
            frequency,
            base.with_changes(
                drive_frequency_hz=frequency,
                drive_amplitude_n=plan.amplitude_n(amplitude),
                part_mass_kg=mass,
            ),
        )
        for mass, amplitude, frequency in plan.settings()
    ]


def _measure(
    points: Sequence[FeederParameters], window_s: float, settle_s: float
) -> tuple[np.ndarray, np.ndarray]:
    summary = simulate_many(list(points), window_s, part=PartSpec(), settle_s=settle_s)
    return summary.mean_part_speed_mps, summary.slip_fraction


def _time_to_travel(
    point: FeederParameters, distance: float, settle_s: float, guess_s: float, limit_s: float
) -> float | None:
    """The first window after ``settle_s`` over which the part travels ``distance`` (to
    :data:`TRAVEL_TOLERANCE_S`), or None if it does not within ``limit_s``.

    The travel grows in bursts (slip) and stands still between them (stick), so the window is
    bracketed and bisected on the exact travel ``mean speed * window``, not iterated."""

    def travel(window: float) -> float:
        speed, _ = _measure([point], window, settle_s)
        return float(speed[0]) * window

    lo, hi = 0.0, min(max(1.25 * guess_s, TRAVEL_TOLERANCE_S), limit_s)
    while not travel(hi) >= distance:
        if hi >= limit_s:
            return None
        lo, hi = hi, min(2.0 * hi, limit_s)
    while hi - lo > TRAVEL_TOLERANCE_S:
        mid = 0.5 * (lo + hi)
        if travel(mid) >= distance:
            hi = mid
        else:
            lo = mid
    return hi


def offline_sweep(
    params: FeederParameters, plan: SweepPlan, progress: Progress | None = None
) -> SweepResult:
    """Run ``plan`` on the plant ``params`` (sharp model). See the module docstring."""
    grid = offline_points(params, plan)
    total = len(grid)
    report = progress or (lambda done, total: None)
    report(0, total)
    speeds = np.full(total, math.nan)
    slips = np.full(total, math.nan)
    durations = np.full(total, math.nan)
    ok = np.ones(total, dtype=bool)
    reasons = [""] * total
    if plan.window_s is not None:
        window = plan.window_s
        for lo in range(0, total, CHUNK_POINTS):
            hi = min(lo + CHUNK_POINTS, total)
            speeds[lo:hi], slips[lo:hi] = _measure(
                [g[3] for g in grid[lo:hi]], window, plan.settle_s
            )
            report(hi, total)
        durations[:] = window
    else:
        distance = plan.distance_m
        assert distance is not None
        probe = min(PROBE_WINDOW_S, plan.max_window_s)
        rough, _ = _measure([g[3] for g in grid], probe, plan.settle_s)
        for k, (_, _, _, point) in enumerate(grid):
            v = float(rough[k])
            guess = distance / v if v > 0.0 else plan.max_window_s
            found = _time_to_travel(point, distance, plan.settle_s, guess, plan.max_window_s)
            durations[k] = found if found is not None else plan.max_window_s
            speed, slip = _measure([point], float(durations[k]), plan.settle_s)
            speeds[k], slips[k] = float(speed[0]), float(slip[0])
            if found is None:
                ok[k] = False
                reasons[k] = (
                    f"the part did not travel {distance:g} m within max_window_s="
                    f"{plan.max_window_s:g} s (mean speed {speeds[k]:.3g} m/s)"
                )
            report(k + 1, total)
    points = []
    for k, (mass, amplitude, frequency, _) in enumerate(grid):
        good = bool(ok[k]) and math.isfinite(float(speeds[k]))
        reason = reasons[k] or ("" if good else "no speed (the part left the track)")
        points.append(
            SweepPoint(
                frequency_hz=frequency,
                amplitude_percent=amplitude,
                amplitude_n=plan.amplitude_n(amplitude),
                part_mass_kg=mass,
                speed_mps=float(speeds[k]),
                duration_s=float(durations[k]),
                slip_fraction=float(slips[k]),
                ok=good,
                reason=reason,
            )
        )
    return SweepResult(tuple(points), "sim", plan.full_scale_force_n)
