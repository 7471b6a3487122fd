"""Many operating points at once (:func:`simulate_many`): carrier and one part per point, from rest,
in parallel on all cores (the sharp solver's ``advance_many``)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from feeder_ros.physics.drive import DriveSchedule
from feeder_ros.physics.errors import SimulationError
from feeder_ros.physics.exact import layout, many_runs
from feeder_ros.physics.live_simulator import _default_drive, _model_vector, _status_reason
from feeder_ros.physics.parameters import FeederParameters, ParameterError
from feeder_ros.physics.parameters import finite_number as _finite
from feeder_ros.physics.results import F64, ManySummary, PartSpec

__all__ = ["simulate_many"]

#: the default part: nominal friction and mass, at the start of the track (frozen: shared)
ONE_PART = PartSpec()


def simulate_many(
    points: Sequence[FeederParameters | tuple[FeederParameters, DriveSchedule | None]],
    duration_s: float,
    part: PartSpec = ONE_PART,
    settle_s: float = 0.0,
) -> ManySummary:
    """Many operating points (carrier + one part each, sharp model), in parallel on all cores.

    Each point is ``params`` or ``(params, drive)``; the part starts at ``part.position_m``.
    Returns the part's exact mean speed and slip fraction over ``duration_s`` (up to its exit if
    it leaves the track). With ``settle_s > 0`` they are measured over the window
    ``[settle_s, settle_s + duration_s]`` instead (the start-up transient left out, as a
    measurement on a running feeder would): each point's run stops at ``settle_s`` on the way
    to record its totals there, and the window's values are the differences of the totals at the
    two instants. A part that leaves the track before ``settle_s`` has a nan speed.
    """
    settle = _finite("settle_s", settle_s, nonnegative=True)
    duration = _finite("duration_s", duration_s, positive=True)
    if settle == 0.0:
        return _simulate_many_from_rest(points, duration, part)[1]
    # one run per point, stopping at settle_s on the way
    head, whole = _simulate_many_from_rest(points, settle + duration, part, settle)
    assert head is not None
    # distances and slip times from rest: speed * span (span ends at the exit for an exited part)
    head_span = np.where(np.isfinite(head.exit_t_s), head.exit_t_s, settle)
    whole_span = np.where(np.isfinite(whole.exit_t_s), whole.exit_t_s, settle + duration)
    window = whole_span - settle
    with np.errstate(invalid="ignore", divide="ignore"):
        speed = (
            whole.mean_part_speed_mps * whole_span - head.mean_part_speed_mps * head_span
        ) / window
        slip = (whole.slip_fraction * whole_span - head.slip_fraction * head_span) / window
    slip = np.clip(slip, 0.0, 1.0)  # a difference of two totals: round-off can leave [0, 1]
    gone = np.isfinite(head.exit_t_s)
    return ManySummary(
        mean_part_speed_mps=np.where(gone, np.nan, speed),
        slip_fraction=np.where(gone, np.nan, slip),
        exit_t_s=whole.exit_t_s,
    )


def _simulate_many_from_rest(
    points: Sequence[FeederParameters | tuple[FeederParameters, DriveSchedule | None]],
    duration_s: float,
    part: PartSpec,
    mid_s: float = 0.0,
) -> tuple[ManySummary | None, ManySummary]:
    """Totals from rest at ``duration_s``, and at ``mid_s`` on the way if ``0 < mid_s``."""
    duration = _finite("duration_s", duration_s, positive=True)
    P = len(points)
    models = np.zeros((P, layout.MODEL_SIZE))
    states = np.zeros((P, layout.STATE_SIZE))
    g_L, g_D, g_mass = np.zeros(P), np.zeros(P), np.zeros(P)
    offsets = np.zeros(P + 1, np.int64)
    starts, omegas, amps, phases, logged = [], [], [], [], []
    for p, point in enumerate(points):
        params, drive = point if isinstance(point, tuple) else (point, None)
        if params.stiffness_model != "sharp":
            raise ParameterError(
                f"point {p}: stiffness_model={params.stiffness_model!r}; "
                "simulate_many is sharp only"
            )
        seg = (drive if drive is not None else _default_drive(params)).segments()
        models[p] = _model_vector(params, log_events=False)
        mass, mu_s, mu_d = part.resolved(params)
        kg = params.gravity_mps2 * params.friction_multiplier
        g_L[p], g_D[p], g_mass[p] = mu_s * kg, mu_d * kg, mass
        model_track = models[p, layout.TRACK]
        models[p, layout.TRACK] = model_track - part.position_m
        states[p, layout.S_MODE] = 1.0
        starts.append(seg.start_s)
        omegas.append(seg.omega_rad_s)
        amps.append(seg.amplitude_n)
        phases.append(seg.phase_rad)
        logged.append(seg.logged)
        offsets[p + 1] = offsets[p] + seg.start_s.size
    results = np.zeros((P, 5))
    results_mid = np.zeros((P, 5))
    many_runs.advance_many(
        models,
        np.concatenate(starts) if P else np.zeros(0),
        np.concatenate(omegas) if P else np.zeros(0),
        np.concatenate(amps) if P else np.zeros(0),
        np.concatenate(phases) if P else np.zeros(0),
        np.concatenate(logged) if P else np.zeros(0, np.int8),
        offsets,
        states,
        g_L,
        g_D,
        g_mass,
        np.full(P, mid_s),
        np.full(P, duration),
        results_mid,
        results,
    )
    bad = np.flatnonzero(results[:, 0] != layout.STATUS_DONE)
    if bad.size:
        shown = [f"point {p} ({_status_reason(int(results[p, 0]))})" for p in bad[:3].tolist()]
        more = f" and {bad.size - 3} more point(s)" if bad.size > 3 else ""
        raise SimulationError(
            f"sharp solver failed at {len(bad)} of {P} point(s): {'; '.join(shown)}{more}"
        )

    def summary(values: F64, span_s: float) -> ManySummary:
        exit_t = values[:, 3]
        span = np.where(np.isfinite(exit_t), exit_t, span_s)
        # displacement of an exited part: track end reached at exit (lab position from the kernel)
        return ManySummary(
            mean_part_speed_mps=values[:, 1] / span,
            slip_fraction=values[:, 2] / span,
            exit_t_s=exit_t,
        )

    mid = summary(results_mid, mid_s) if 0.0 < mid_s < duration else None
    return mid, summary(results, duration)
