"""The report of a design search (:mod:`feeder_ros.design.optimizer`): the printed summary and
sensitivity table, and the files ``feeder design --output DIR`` writes.

* ``design.json``: everything printed, plus bounds, conditions, plant and the convergence history;
* ``sensitivity.csv``: :data:`~feeder_ros.design.sensitivity.SENSITIVITY_COLUMNS` per variable;
* ``optimum_params.yaml``: the optimum as the simulator's ``ros__parameters``, and
  ``robust_params.yaml`` the robust optimum (:mod:`~feeder_ros.design.robust_search`) alike
  (``platform_simulator --ros-args --params-file optimum_params.yaml``, or
  ``feeder sim --config optimum_params.yaml``);
* ``design_convergence.png``; ``design_speed_map.png``, the speed over the two variables it is
  most sensitive to, the others at the optimum, the designs that hold their conditions when built
  hatched; with a robust optimum, ``design_robust_map.png``, the same two variables with the others
  at the robust optimum (a different slice of the space: each optimum on its own map).

Every file is written atomically (:mod:`feeder_ros.atomic_files`).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from feeder_ros.atomic_files import atomic_text
from feeder_ros.csv_cells import csv_cell
from feeder_ros.design.optimizer import DesignEvaluation, DesignProblem, DesignResult
from feeder_ros.design.robust_search import RobustResult
from feeder_ros.design.sensitivity import (
    SENSITIVITY_COLUMNS,
    SensitivityRow,
    SpeedMap,
    speed_map,
)
from feeder_ros.design.space import DesignSpace
from feeder_ros.figures import save_figure
from feeder_ros.physics.parameters import FeederParameters

__all__ = [
    "PARAMS_FILE_NODE",
    "evaluation_record",
    "plot_convergence",
    "plot_speed_map",
    "sensitivity_text",
    "summary",
    "write_report",
]

#: the node key of the written parameter file (any namespace, as config/platform_simulator.yaml)
PARAMS_FILE_NODE = "/**/platform_simulator"

_SCALES = {"m": (1e3, "mm"), "m/s": (1e3, "mm/s")}


def _fmt(value: float, digits: int = 4) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if not math.isfinite(value):
        return "nan"
    return f"{value:.{digits}g}"


def _bound_note(space: DesignSpace, name: str, value: float, scale: float) -> str:
    variable = space.variables[space.names.index(name)]
    tolerance = 1e-3 * (variable.upper - variable.lower)
    bounds = f"[{_fmt(variable.lower * scale)}, {_fmt(variable.upper * scale)}]"
    if value <= variable.lower + tolerance:
        return f"{bounds} at lower bound"
    if value >= variable.upper - tolerance:
        return f"{bounds} at upper bound"
    return bounds


def summary(result: DesignResult, reference: DesignEvaluation, plant_label: str, seed: int) -> str:
    problem = result.problem
    space, limits, window = problem.space, problem.limits, problem.window
    plant = problem.plant
    head = f"objective {problem.objective}"
    if problem.target_speed_mps is not None:
        head += f" (target {problem.target_speed_mps * 1e3:g} mm/s)"
    lines = [
        f"{head}; plant {plant_label}: c = {plant.damping_ns_per_m:g} N*s/m, "
        f"mu_s = {plant.static_friction:g}, slip threshold a_s = "
        f"{plant.stick_limit_mps2:.4g} m/s^2",
        f"each design: one part from rest, mean speed and carrier peaks over "
        f"[{window.settle_s:g}, {window.settle_s + window.window_s:g}] s "
        f"(transient left {window.transient_left(plant):.1e})",
        "",
        f"{'':26s}{'case study':>14s}{'optimum':>14s}   bounds / condition",
    ]
    ref, best = reference, result.best
    for name in space.names:
        spec_unit = space.variables[space.names.index(name)].unit
        scale, unit = _SCALES.get(spec_unit, (1.0, spec_unit))
        label = f"{name} [{unit}]"
        r, b = float(getattr(ref.params, name)), float(getattr(best.params, name))
        note = _bound_note(space, name, b, scale)
        lines.append(f"{label:26s}{_fmt(r * scale):>14s}{_fmt(b * scale):>14s}   {note}")
    rm = limits.required_margin

    def row(label: str, r: float | bool, b: float | bool, note: str = "") -> None:
        lines.append(f"{label:26s}{_fmt(r):>14s}{_fmt(b):>14s}   {note}".rstrip())

    rmar, bmar = ref.margins, best.margins
    row("part speed [mm/s]", ref.speed_mps * 1e3, best.speed_mps * 1e3)
    row("slip fraction", ref.slip_fraction, best.slip_fraction)
    row("forward peak [m/s^2]", rmar.forward_peak_mps2, bmar.forward_peak_mps2)
    row("backward peak [m/s^2]", rmar.backward_peak_mps2, bmar.backward_peak_mps2)
    row("forward margin", rmar.forward_margin, bmar.forward_margin, f">= {rm:g} (parts stick)")
    row("backward margin", rmar.backward_margin, bmar.backward_margin, f">= {rm:g} (parts slip)")
    row(
        "K_f/K_b",
        rmar.stiffness_ratio,
        bmar.stiffness_ratio,
        f">= {limits.min_stiffness_ratio:g}",
    )
    row("slenderness L/h", rmar.slenderness, bmar.slenderness, f">= {limits.min_slenderness:g}")
    row(
        "stroke [mm]",
        rmar.stroke_m * 1e3,
        bmar.stroke_m * 1e3,
        f"<= {limits.max_stroke_m * 1e3:g}",
    )
    row("in set S", rmar.in_set_s(rm), bmar.in_set_s(rm))
    row("meets every condition", problem.feasible(ref), result.feasible)
    lines += [
        "",
        f"{result.evaluations} designs evaluated in {result.wall_time_s:.1f} s "
        f"({result.generations} generations, seed {seed}): {result.message}",
    ]
    return "\n".join(lines)


def sensitivity_text(rows: Sequence[SensitivityRow]) -> str:
    lines = [
        "sensitivity at the optimum (steps -/+; speed change in %; elasticity = % speed per % "
        "variable (central); margin slopes per relative change; meets = every condition met):",
        f"{'variable':20s}{'step -/+':>20s}{'speed -/+ %':>16s}{'elasticity':>12s}"
        f"{'d fwd margin':>14s}{'d bwd margin':>14s}{'meets -/+':>11s}",
    ]
    for r in rows:
        steps = f"{_fmt(r.value_minus)}/{_fmt(r.value_plus)}"
        speeds = f"{100 * r.speed_change_minus:+.2f}/{100 * r.speed_change_plus:+.2f}"
        meets = f"{_fmt(r.feasible_minus)}/{_fmt(r.feasible_plus)}"
        lines.append(
            f"{r.variable:20s}{steps:>20s}{speeds:>16s}{r.speed_elasticity:>12.3f}"
            f"{r.forward_margin_slope:>14.3f}{r.backward_margin_slope:>14.3f}{meets:>11s}"
        )
    return "\n".join(lines)


def _clean(value: Any) -> Any:
    """JSON-safe: nan/inf as null, numpy scalars as Python numbers."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, np.bool_ | bool):
        return bool(value)
    if isinstance(value, np.integer | int):
        return int(value)
    if isinstance(value, np.floating | float):
        return float(value) if math.isfinite(value) else None
    return value


def evaluation_record(problem: DesignProblem, evaluation: DesignEvaluation) -> dict[str, Any]:
    margins = evaluation.margins
    return {
        "design": {name: getattr(evaluation.params, name) for name in problem.space.names},
        "speed_mps": evaluation.speed_mps,
        "slip_fraction": evaluation.slip_fraction,
        "stick_limit_mps2": margins.stick_limit_mps2,
        "forward_peak_mps2": margins.forward_peak_mps2,
        "backward_peak_mps2": margins.backward_peak_mps2,
        "forward_margin": margins.forward_margin,
        "backward_margin": margins.backward_margin,
        "stroke_m": margins.stroke_m,
        "stiffness_ratio": margins.stiffness_ratio,
        "slenderness": margins.slenderness,
        "in_set_s": margins.in_set_s(problem.limits.required_margin),
        "constraints": dict(
            zip(problem.constraint_names, problem.constraints(evaluation).tolist(), strict=True)
        ),
        "feasible": problem.feasible(evaluation),
        "parameters": evaluation.params.as_dict(),
    }


def write_report(
    out_dir: Path,
    result: DesignResult,
    reference: DesignEvaluation,
    rows: Sequence[SensitivityRow],
    seed: int,
    map_points: int,
    robustness: dict[str, object] | None = None,
    robust: RobustResult | None = None,
    robust_built: dict[str, object] | None = None,
) -> list[Path]:
    """Write the report files into ``out_dir`` (created if needed); returns their paths. The
    speed map simulates ``map_points`` x ``map_points`` designs around the optimum and, with a
    ``robust`` result, the carrier of each one's drawn plants (its hatched robust region: 14,400
    carrier runs at the defaults, about 5 s); the robust optimum gets its own map (its slice of the
    space). ``robustness`` and ``robust_built`` are the optimum's and the robust optimum's
    :meth:`~feeder_ros.design.robustness.Robustness.record`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    problem = result.problem
    paths: list[Path] = []

    record = {
        "objective": problem.objective,
        "target_speed_mps": problem.target_speed_mps,
        "seed": seed,
        "generations": result.generations,
        "evaluations": result.evaluations,
        "wall_time_s": result.wall_time_s,
        "message": result.message,
        "feasible": result.feasible,
        "objective_value": result.objective_value,
        "bounds": {v.name: [v.lower, v.upper] for v in problem.space.variables},
        "conditions": asdict(problem.limits),
        "evaluation": asdict(problem.window),
        "plant": problem.plant.as_dict(),
        "optimum": evaluation_record(problem, result.best),
        "reference": evaluation_record(problem, reference),
        "robustness": robustness,
        "robust": None if robust is None else {**robust.record(problem), "as_built": robust_built},
        "history": [list(item) for item in result.history],
    }
    path = out_dir / "design.json"
    with atomic_text(path) as stream:
        json.dump(_clean(record), stream, indent=2, allow_nan=False)
        stream.write("\n")
    paths.append(path)

    path = out_dir / "sensitivity.csv"
    with atomic_text(path) as stream:
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(SENSITIVITY_COLUMNS)
        for r in rows:
            writer.writerow([csv_cell(r.as_dict()[name]) for name in SENSITIVITY_COLUMNS])
    paths.append(path)

    what = f"objective {problem.objective}, seed {seed}"
    paths.append(_write_params(out_dir / "optimum_params.yaml", result.params, f"Optimum ({what})"))
    if robust is not None and robust.best is not None:
        title = f"Robust optimum (probability >= {robust.probability:g}; {what})"
        paths.append(_write_params(out_dir / "robust_params.yaml", robust.best.params, title))

    paths.append(plot_convergence(out_dir / "design_convergence.png", result, reference))
    ranked = sorted(rows, key=lambda r: -abs(r.speed_elasticity) if _finite(r) else 0.0)
    if len(ranked) >= 2:
        tolerances = robust.tolerances if robust is not None else None
        axes = (ranked[0].variable, ranked[1].variable)
        grid = speed_map(problem, result.params, *axes, map_points, tolerances)
        path = out_dir / "design_speed_map.png"
        paths.append(plot_speed_map(path, grid, result.params, "optimum"))
        if robust is not None and robust.best is not None:
            grid = speed_map(problem, robust.best.params, *axes, map_points, robust.tolerances)
            path = out_dir / "design_robust_map.png"
            paths.append(plot_speed_map(path, grid, robust.best.params, "robust optimum"))
    return paths


def _write_params(path: Path, params: FeederParameters, title: str) -> Path:
    """A design as the simulator's ``ros__parameters`` file."""
    with atomic_text(path) as stream:
        stream.write(
            f"# {title} of `feeder design`: the simulator's model parameters.\n"
            f"# platform_simulator --ros-args --params-file {path.name}, or "
            f"feeder sim --config {path.name}\n"
        )
        yaml.safe_dump(
            {PARAMS_FILE_NODE: {"ros__parameters": params.as_dict()}},
            stream,
            sort_keys=False,
            default_flow_style=False,
        )
    return path


def _finite(row: SensitivityRow) -> bool:
    return math.isfinite(row.speed_elasticity)


def plot_convergence(path: Path, result: DesignResult, reference: DesignEvaluation) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    problem = result.problem
    done = np.array([h[0] for h in result.history], dtype=np.float64)
    best = np.array([h[1] for h in result.history], dtype=np.float64)
    fig = Figure(figsize=(7, 4), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    if problem.objective == "max-speed":
        ax.step(done, -best * 1e3, where="post", label="best design in set S")
        ax.axhline(
            reference.speed_mps * 1e3, color="k", ls="--", label="case study (same evaluation)"
        )
        ax.set(ylabel="part speed [mm/s]")
    else:
        ax.step(done, best, where="post", label="least amplitude reaching the target")
        ax.axhline(
            reference.params.drive_amplitude_n, color="k", ls="--", label="case study amplitude"
        )
        ax.set(ylabel="drive amplitude A [N]")
    ax.set(xlabel="designs evaluated", title=f"Design search ({problem.objective})")
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)


def plot_speed_map(path: Path, grid: SpeedMap, marked: FeederParameters, label: str) -> Path:
    """The speed map ``grid`` (a slice through ``marked``, starred as ``label``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    fig = Figure(figsize=(7, 5.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    speed = grid.speed_mps * 1e3
    finite = speed[np.isfinite(speed)]
    norm = Normalize(float(finite.min()), float(finite.max())) if finite.size else Normalize()
    # every design faded, those meeting every condition on top at full colour
    ax.pcolormesh(grid.x, grid.y, speed, shading="nearest", cmap="viridis", norm=norm, alpha=0.3)
    mesh = ax.pcolormesh(
        grid.x,
        grid.y,
        np.ma.masked_where(~grid.feasible, speed),
        shading="nearest",
        cmap="viridis",
        norm=norm,
    )
    fig.colorbar(mesh, ax=ax, label="part speed [mm/s]")
    extra: list[Patch] = []
    if grid.robust is not None and grid.robust.any():
        # hatched: designs that meet every condition in the promised share of built feeders
        ax.contourf(
            grid.x,
            grid.y,
            grid.robust.astype(float),
            levels=[0.5, 1.5],
            colors="none",
            hatches=["///"],
        )
        if not grid.robust.all():
            ax.contour(grid.x, grid.y, grid.robust.astype(float), levels=[0.5], colors="white")
        extra.append(
            Patch(facecolor="none", edgecolor="black", hatch="///", label="robust when built")
        )
    ax.plot(getattr(marked, grid.x_name), getattr(marked, grid.y_name), "r*", ms=14, label=label)
    ax.set(
        xlabel=grid.x_name,
        ylabel=grid.y_name,
        title=f"Part speed, other variables at the {label}\n"
        "(faded: a condition of set S or validity not met)",
    )
    handles = [*ax.get_legend_handles_labels()[0], *extra]
    ax.legend(handles=handles, loc="best", fontsize="small")
    return save_figure(fig, path)
