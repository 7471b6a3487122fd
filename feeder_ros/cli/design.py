"""``feeder design``: search the carrier's design for the fastest parts (or a target speed with the
least drive force) under the paper's stick-slip conditions, and report it.

The plant (masses, friction, damping, ...) is the simulator's YAML as ``feeder sim`` reads it
(:func:`feeder_ros.cli.sim.load_parameters`; the damped ``realistic`` preset by default, so that the
steady state is well posed), the searched variables and their bounds, the conditions, the
evaluation window and the reference design (the paper's case study) are the design file
(``config/design.yaml``). The reference is evaluated exactly as every candidate is (same plant,
part, window), and printed beside the optimum.

``--output DIR`` writes ``design.json`` (everything printed, plus the convergence history),
``sensitivity.csv``, ``design_convergence.png``, ``design_speed_map.png`` (speed over the two
variables it is most sensitive to) and ``optimum_params.yaml``, the optimum as the simulator's
``ros__parameters`` (``platform_simulator --ros-args --params-file DIR/optimum_params.yaml``, or
``feeder sim --config DIR/optimum_params.yaml``).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from feeder_ros.cli.arguments import positive_int
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.progress import ProgressBar
from feeder_ros.cli.sim import (
    add_plant_arguments,
    atomic_text,
    default_config_path,
    plant_from_arguments,
)
from feeder_ros.design.optimizer import (
    OBJECTIVES,
    DesignEvaluation,
    DesignProblem,
    DesignResult,
    evaluate_designs,
    optimize,
    population_size,
)
from feeder_ros.design.sensitivity import (
    SENSITIVITY_COLUMNS,
    SensitivityRow,
    SpeedMap,
    sensitivity_table,
    speed_map,
)
from feeder_ros.design.space import DesignConfig, DesignSpace, load_design_config
from feeder_ros.figures import save_figure
from feeder_ros.physics.parameters import FeederParameters

__all__ = ["DESIGN_NAME", "HELP", "PARAMS_FILE_NODE", "add_arguments", "run"]

HELP = (
    "search the carrier design (L_f, L_b, plates, angle, drive) for the fastest parts under the "
    "stick-slip conditions"
)
DESIGN_NAME = "design.yaml"
#: the node key of the written parameter file (any namespace, as config/platform_simulator.yaml)
PARAMS_FILE_NODE = "/**/platform_simulator"


def _speed(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive speed in m/s")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--space", type=Path, metavar="YAML", help=f"design file (default: config/{DESIGN_NAME})"
    )
    add_plant_arguments(
        parser, "realistic", "fix one plant parameter (repeatable), e.g. --set static_friction=0.3"
    )
    parser.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default="max-speed",
        help="max-speed: fastest parts; min-force: --target-speed with the least drive amplitude",
    )
    parser.add_argument(
        "--target-speed", type=_speed, metavar="M_PER_S", help="min-force: part speed to reach"
    )
    parser.add_argument("--seed", type=int, default=0, help="optimiser seed (default 0)")
    parser.add_argument(
        "--generations", type=positive_int, default=30, help="generations at most (default 30)"
    )
    parser.add_argument(
        "--population",
        type=positive_int,
        default=42,
        help="designs per generation, rounded up to a multiple of the variables (default 42)",
    )
    parser.add_argument(
        "--max-evaluations",
        type=positive_int,
        metavar="N",
        help="designs simulated at most (caps --generations)",
    )
    parser.add_argument(
        "--map-points",
        type=positive_int,
        default=15,
        help="speed-map grid points per axis (--output; default 15)",
    )
    parser.add_argument("--output", type=Path, metavar="DIR", help="write the report files here")
    parser.add_argument(
        "--progress", action="store_true", help="show a progress bar even if stderr is not a TTY"
    )


def _load(args: argparse.Namespace) -> tuple[DesignConfig, FeederParameters, str]:
    config_dir = default_config_path().parent
    space_path = Path(args.space) if args.space is not None else config_dir / DESIGN_NAME
    if not space_path.is_file():
        raise CommandError(f"--space {space_path}: no such file")
    design = load_design_config(space_path)
    searched = set(design.space.names)
    for item in args.overrides:
        name = item.partition("=")[0].strip()
        if name in searched:
            raise CommandError(
                f"--set {item!r}: {name} is searched (variables of {space_path}); "
                "remove it there to fix its value"
            )
    plant, plant_path, preset = plant_from_arguments(args)
    label = f"{plant_path.name}" + (f", preset {preset}" if preset else "")
    return design, plant, label


def run(args: argparse.Namespace) -> int:
    if args.objective == "min-force" and args.target_speed is None:
        raise CommandError("--objective min-force needs --target-speed (m/s)")
    if args.objective == "max-speed" and args.target_speed is not None:
        raise CommandError("--target-speed is for --objective min-force")
    design, plant, plant_label = _load(args)
    problem = DesignProblem(
        space=design.space,
        plant=plant,
        limits=design.limits,
        window=design.window,
        objective=args.objective,
        target_speed_mps=args.target_speed,
    )
    reference = evaluate_designs([design.reference_parameters(plant)], design.window)[0]
    for line in _warnings(problem):
        print(f"feeder design: warning: {line}", file=sys.stderr)

    _, members = population_size(design.space, args.population)
    show = bool(args.progress) or sys.stderr.isatty()
    bar = ProgressBar("design search", members * (args.generations + 1), show)

    def progress(done: int, planned: int) -> None:
        bar.total = float(planned)
        bar.update(done)

    try:
        result = optimize(
            problem,
            seed=args.seed,
            generations=args.generations,
            population=args.population,
            max_evaluations=args.max_evaluations,
            progress=progress,
        )
    finally:
        bar.close()
    rows = sensitivity_table(problem, result.params)
    print(summary(result, reference, plant_label, args.seed))
    print(sensitivity_text(rows))
    if args.output is not None:
        for path in write_report(Path(args.output), result, reference, rows, args):
            print(f"wrote {path}")
    if not result.feasible:
        print(
            "feeder design: no evaluated design meets every condition; the least violating one is "
            "reported (widen the bounds, relax the conditions or search longer)",
            file=sys.stderr,
        )
        return 1
    return 0


def _warnings(problem: DesignProblem) -> list[str]:
    out = []
    left = problem.window.transient_left(problem.plant)
    if problem.plant.damping_ns_per_m == 0.0:
        out.append(
            "undamped plant (c = 0): the carrier never settles and the case study is chaotic; "
            "speeds and peaks are statistics of the window, not of a steady state"
        )
    elif left > 1e-2:
        out.append(
            f"{left:.1%} of the start-up transient is left at settle_s = "
            f"{problem.window.settle_s:g} s: raise evaluation.settle_s"
        )
    return out


# -- report -------------------------------------------------------------------------------
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
    args: argparse.Namespace,
) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    problem = result.problem
    paths: list[Path] = []

    record = {
        "objective": problem.objective,
        "target_speed_mps": problem.target_speed_mps,
        "seed": args.seed,
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
            writer.writerow([_csv(r.as_dict()[name]) for name in SENSITIVITY_COLUMNS])
    paths.append(path)

    path = out_dir / "optimum_params.yaml"
    with atomic_text(path) as stream:
        stream.write(
            f"# Optimum of `feeder design` (objective {problem.objective}, seed {args.seed}): "
            "the simulator's model parameters.\n"
            "# platform_simulator --ros-args --params-file optimum_params.yaml, or "
            "feeder sim --config optimum_params.yaml\n"
        )
        yaml.safe_dump(
            {PARAMS_FILE_NODE: {"ros__parameters": result.params.as_dict()}},
            stream,
            sort_keys=False,
            default_flow_style=False,
        )
    paths.append(path)

    paths.append(plot_convergence(out_dir / "design_convergence.png", result, reference))
    ranked = sorted(rows, key=lambda r: -abs(r.speed_elasticity) if _finite(r) else 0.0)
    if len(ranked) >= 2:
        grid = speed_map(
            problem, result.params, ranked[0].variable, ranked[1].variable, args.map_points
        )
        paths.append(plot_speed_map(out_dir / "design_speed_map.png", grid, result))
    return paths


def _finite(row: SensitivityRow) -> bool:
    return math.isfinite(row.speed_elasticity)


def _csv(value: object) -> str:
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value)
    return str(value)


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


def plot_speed_map(path: Path, grid: SpeedMap, result: DesignResult) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

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
    ax.plot(
        getattr(result.params, grid.x_name),
        getattr(result.params, grid.y_name),
        "r*",
        ms=14,
        label="optimum",
    )
    ax.set(
        xlabel=grid.x_name,
        ylabel=grid.y_name,
        title="Part speed (faded: a condition of set S or validity not met)",
    )
    ax.legend(loc="best", fontsize="small")
    return save_figure(fig, path)
