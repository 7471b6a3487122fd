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
* **Distance instead of a window** (the paper timed parts over 8.5 cm): the distance is measured
  along the track, as light barriers on the track see it (the live sweep's part sensors), and
  timed from ``settle_s`` to the first instant the part has moved ``distance_m`` along the
  track. One exact run per point
  (:class:`~feeder_ros.physics.simulation.FeederSimulator`): at ``settle_s`` the track is cut
  (``set_parameters``) to end ``distance_m`` ahead of the part, and the engine locates the part's
  exit like any other event, exact to round-off. (A part advances in bursts, slip, with stands
  between them, stick, and at times slips back: neither ``distance / speed`` nor a bisection on
  the travel finds that first instant.) The reported ``duration_s`` is that time and the speed
  ``distance_m / duration_s``. The part starts at :data:`TRAVEL_ORIGIN_M` on the endless track, so
  a part that slid back during the settle time still has a track end ahead of it. A point whose
  part does not get there within ``max_window_s`` is measured over ``max_window_s`` (its travel
  along the track over that time) and marked not ok with the reason (the paper kept only moving
  parts).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from feeder_ros.identification.sweep import SweepPlan, SweepPoint, SweepResult
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import FeederSimulator, PartSpec, simulate_many

__all__ = ["ENDLESS_TRACK_M", "TRAVEL_ORIGIN_M", "offline_points", "offline_sweep", "travel_time"]

#: track length of the offline points: no part reaches its end within any window
ENDLESS_TRACK_M = 1.0e6
#: distance mode: where the part starts on the endless track (room to slide back; positions
#: there still resolve 1e-14 m)
TRAVEL_ORIGIN_M = 100.0
#: distance mode: simulated seconds per advance while waiting for the part to arrive
TRAVEL_CHUNK_S = 2.0
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


def travel_time(
    point: FeederParameters, distance_m: float, settle_s: float, limit_s: float
) -> tuple[float | None, float, float]:
    """How long after ``settle_s`` the part of ``point`` (put down at rest at t = 0) needs to move
    ``distance_m`` forward along the track: ``(duration_s or None, speed m/s, slip fraction)``.

    The duration is exact: the engine's exit event on a track cut at ``settle_s`` to end
    ``distance_m`` ahead of the part. The speed is ``distance_m / duration_s`` and the slip
    fraction is over that window. None: not within ``limit_s``; speed (the travel along the track)
    and slip fraction are then over ``limit_s``."""
    if not (math.isfinite(distance_m) and distance_m > 0.0):
        raise ValueError(f"distance_m={distance_m!r} must be a positive number")
    sim = FeederSimulator(point, (PartSpec(position_m=TRAVEL_ORIGIN_M),))
    y0, slip0 = TRAVEL_ORIGIN_M, 0.0  # track position of the part and its slip time at settle_s
    if settle_s > 0.0:
        start = sim.advance(settle_s)
        if math.isfinite(float(start.part_exit_t_s[0])):
            raise ValueError(f"the part left the track before settle_s={settle_s!r} s")
        y0 = float(start.part_end_x_m[0]) - sim.carrier_state[0]  # lab - carrier
        slip0 = float(start.part_slip_time_s[0])
    sim.set_parameters(point.with_changes(track_length_m=y0 + distance_m))
    end = settle_s + limit_s
    while True:
        result = sim.advance(min(sim.time_s + TRAVEL_CHUNK_S, end))
        exit_t = float(result.part_exit_t_s[0])
        if math.isfinite(exit_t) or sim.time_s >= end:
            break
    slip = float(result.part_slip_time_s[0]) - slip0
    if math.isfinite(exit_t):
        duration = exit_t - settle_s
        return duration, distance_m / duration, min(max(slip / duration, 0.0), 1.0)
    travel = float(result.part_end_x_m[0]) - sim.carrier_state[0] - y0
    return None, travel / limit_s, min(max(slip / limit_s, 0.0), 1.0)


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
        for k, (_, _, _, point) in enumerate(grid):
            found, speeds[k], slips[k] = travel_time(
                point, distance, plan.settle_s, plan.max_window_s
            )
            durations[k] = found if found is not None else plan.max_window_s
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
