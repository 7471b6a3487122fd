"""The report of ``feeder identify``: the printed summary, ``fit.json``, ``sweep.csv``, the
Fig. 9/Fig. 10 plots and the speed model file the drive interface loads.

Every file is written atomically (:mod:`feeder_ros.atomic_files`); ``fit.json`` has ``null`` where
a value is not finite (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from feeder_ros.atomic_files import atomic_text
from feeder_ros.identification.group_fit import FitSettings, GroupFit
from feeder_ros.identification.sweep import SweepPlan, SweepResult

__all__ = ["PAPER_FIT_PERCENT", "fit_json", "summary", "write_model_file", "write_outputs"]

#: the paper's fit for its 31 g vehicle (Eq. 24), for the summary
PAPER_FIT_PERCENT = 63.0


def _complex_pairs(values: Sequence[complex]) -> list[list[float]]:
    return [[float(v.real), float(v.imag)] for v in values]


def _pole_table(poles: Sequence[complex]) -> list[dict[str, float]]:
    """Each pole as natural frequency |p|/2 pi [Hz] and damping ratio -Re p / |p|."""
    return [
        {"natural_frequency_hz": abs(p) / (2.0 * math.pi), "damping_ratio": -p.real / abs(p)}
        for p in poles
        if p.imag >= 0.0 and abs(p) > 0.0
    ]


def fit_json(
    result: SweepResult,
    fits: Sequence[GroupFit],
    plan: SweepPlan | None,
    settings: FitSettings,
    plant: dict[str, Any] | None,
) -> dict[str, Any]:
    groups = []
    for fit in fits:
        g = fit.group
        entry: dict[str, Any] = {
            "amplitude_percent": g.amplitude_percent,
            "amplitude_n": g.amplitude_n,
            "part_mass_kg": g.part_mass_kg,
            "points": int(g.frequency_hz.size),
            "excluded": dict(g.excluded),
            "frequency_range_hz": [float(g.frequency_hz.min()), float(g.frequency_hz.max())]
            if g.frequency_hz.size
            else None,
            "measured_peak_hz": float(g.frequency_hz[g.speed_mps.argmax()])
            if g.frequency_hz.size
            else None,
            "measured_peak_speed_mps": float(g.speed_mps.max()) if g.speed_mps.size else None,
            "error": fit.error or None,
            "orders_left_out": fit.left_out,
            "orders": [
                {
                    "zeros": s.zeros,
                    "poles": s.poles,
                    "parameters": s.parameters,
                    "fit_percent": s.fit_percent,
                    "holdout_fit_percent": s.holdout_fit_percent,
                }
                for s in fit.scores
            ],
        }
        if fit.best is not None:
            model = fit.best.fit.model
            entry.update(
                chosen_order={"zeros": fit.best.zeros, "poles": fit.best.poles},
                gain=model.gain,
                zeros=_complex_pairs(model.zeros),
                poles=_complex_pairs(model.poles),
                poles_hz=_pole_table(model.poles),
                fit_percent=fit.best.fit_percent,
                holdout_fit_percent=fit.best.holdout_fit_percent,
                residual_rms_mps=fit.best.fit.residual_rms_mps,
                peak_frequency_hz=fit.peak_hz,
                model=model.to_dict(),
            )
        groups.append(entry)
    return {
        "source": result.source,
        "points": len(result),
        "points_ok": result.ok_count,
        "full_scale_force_n": result.full_scale_force_n,
        "plan": None if plan is None else plan.as_dict(),
        "plant": plant,
        "fit": {
            "orders": [list(o) for o in settings.orders],
            "min_speed_mps": settings.min_speed_mps,
            "folds": settings.folds,
            "criterion": "Eq. 23 on magnitudes, unit weights; fit % = NRMSE fit "
            "100*(1 - |v - v_hat| / |v - mean v|); order chosen by hold-out fit "
            "(interleaved folds over frequency), ties within 1 point to fewer parameters",
        },
        "paper_fit_percent": PAPER_FIT_PERCENT,
        "groups": groups,
    }


def _json_safe(value: Any) -> Any:
    """NaN/inf become null (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    return value


def write_model_file(path: Path, result: SweepResult, fits: Sequence[GroupFit]) -> int:
    from feeder_ros.identification.rational_fit import IdentificationError
    from feeder_ros.identification.speed_model_file import (
        ModelEntry,
        SpeedModelFile,
        save_speed_model,
    )

    entries = []
    for fit in fits:
        if fit.best is None:
            continue
        g = fit.group
        entries.append(
            ModelEntry(
                amplitude_percent=g.amplitude_percent,
                amplitude_n=g.amplitude_n,
                part_mass_kg=g.part_mass_kg,
                frequency_range_hz=(float(g.frequency_hz.min()), float(g.frequency_hz.max())),
                fit_percent=fit.best.fit_percent,
                model=fit.best.fit.model,
            )
        )
    if not entries:
        raise IdentificationError(f"{path}: no fitted model to write")
    full_scale = result.full_scale_force_n
    if not math.isfinite(full_scale):
        raise IdentificationError(f"{path}: the sweep gives no drive full scale")
    save_speed_model(
        path, SpeedModelFile(full_scale, tuple(entries), f"feeder identify ({result.source})")
    )
    return len(entries)


def summary(result: SweepResult, fits: Sequence[GroupFit], wall_s: float) -> str:
    lines = [
        f"sweep: {len(result)} point{'' if len(result) == 1 else 's'}, {result.ok_count} usable, "
        f"source {result.source} ({wall_s:.1f} s)"
    ]
    if not fits:
        return "\n".join(lines)
    header = (
        f"{'amplitude':>9} {'mass':>6} {'points':>6} {'order':>5} {'fit %':>6} {'hold-out %':>10} "
        f"{'peak Hz':>8} {'data peak':>9}  poles (natural Hz / damping)"
    )
    lines += [header, "-" * len(header)]
    for fit in fits:
        g = fit.group
        head = f"{g.amplitude_percent:>7g} % {g.part_mass_kg * 1e3:>4g} g {g.frequency_hz.size:>6d}"
        if fit.best is None:
            lines.append(f"{head}  not fitted: {fit.error}")
            continue
        best = fit.best
        data_peak = float(g.frequency_hz[g.speed_mps.argmax()])
        poles = ", ".join(
            f"{p['natural_frequency_hz']:.2f}/{p['damping_ratio']:.3f}"
            for p in _pole_table(best.fit.model.poles)
        )
        lines.append(
            f"{head} {best.zeros:>3d}/{best.poles:<1d} {best.fit_percent:>6.1f} "
            f"{best.holdout_fit_percent:>10.1f} {fit.peak_hz:>8.2f} {data_peak:>9.2f}  {poles}"
        )
    fitted = [f.best.fit_percent for f in fits if f.best is not None]
    if fitted:
        lines.append(
            f"fit % from {min(fitted):.1f} to {max(fitted):.1f} (the paper: "
            f"{PAPER_FIT_PERCENT:g} % and 50 % on its feeder)"
        )
    for fit in fits:
        for note in fit.left_out:
            lines.append(f"note: {fit.group.label}: {note}")
    return "\n".join(lines)


def write_points(directory: Path, result: SweepResult) -> Path:
    """The sweep's measured points as ``directory/sweep.csv`` (written whole or not at all)."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "sweep.csv"
    with atomic_text(path) as stream:
        result.write_csv(stream)
    return path


def write_outputs(
    directory: Path,
    result: SweepResult,
    fits: Sequence[GroupFit],
    document: dict[str, Any] | None,
) -> list[Path]:
    from feeder_ros.identification.plots import plot_bode_magnitude, plot_speed_sweep

    written = [write_points(directory, result)]
    if result.ok_count:
        written.append(plot_speed_sweep(result, directory / "fig9.png"))
    if document is not None:
        with atomic_text(directory / "fit.json") as stream:
            json.dump(_json_safe(document), stream, indent=2)
            stream.write("\n")
        written.append(directory / "fit.json")
        models = {f.key: f.best.fit.model for f in fits if f.best is not None}
        peaks = {f.key: f.peak_hz for f in fits if f.best is not None}
        groups = [f.group for f in fits if f.group.frequency_hz.size]
        if groups:
            written.append(plot_bode_magnitude(groups, models, directory / "fig10.png", peaks))
    return written
