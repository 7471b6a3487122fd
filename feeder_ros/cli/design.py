"""``feeder design``: search the carrier's design for the fastest parts (or a target speed with the
least drive force) under the paper's stick-slip conditions, and report it.

The plant (masses, friction, damping, ...) is the simulator's YAML as ``feeder sim`` reads it
(:func:`feeder_ros.cli.sim.load_parameters`; the damped ``realistic`` preset by default, so that the
steady state is well posed), the searched variables and their bounds, the conditions, the
evaluation window and the reference design (the paper's case study) are the design file
(``config/design.yaml``). The reference is evaluated exactly as every candidate is (same plant,
part, window), and printed beside the optimum.

``--output DIR`` writes ``design.json`` (everything printed, plus the convergence history),
``sensitivity.csv``, ``design_convergence.png``, ``design_speed_map.png`` and
``design_robust_map.png`` (speed over the two variables it is most sensitive to, through the
optimum and the robust optimum), ``robust_params.yaml`` (the design that holds its conditions
within the tolerances, :mod:`~feeder_ros.design.robust_search`) and ``optimum_params.yaml``, the
optimum, each as the simulator's ``ros__parameters`` (``platform_simulator --ros-args
--params-file DIR/optimum_params.yaml``, or ``feeder sim --config DIR/robust_params.yaml``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from feeder_ros.cli.arguments import int_at_least, non_negative_int, positive_int
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.outputs import check_output_dir, finish_output_dir, output_path
from feeder_ros.cli.progress import ProgressBar
from feeder_ros.cli.sim import add_plant_arguments, default_config_path, plant_from_arguments
from feeder_ros.design.objectives import OBJECTIVES

# the optimizer, its report (scipy, matplotlib) and the physics core are imported where they are
# used, so that ``feeder --help`` does not load them
if TYPE_CHECKING:
    from feeder_ros.design.optimizer import DesignProblem, DesignResult
    from feeder_ros.design.robust_search import RobustResult
    from feeder_ros.design.space import DesignConfig
    from feeder_ros.physics.parameters import FeederParameters

__all__ = ["DESIGN_NAME", "EPILOG", "HELP", "add_arguments", "run"]

HELP = (
    "search the carrier design (L_f, L_b, plates, angle, drive) for the fastest parts under the "
    "stick-slip conditions"
)
DESIGN_NAME = "design.yaml"
EPILOG = """\
examples:
  # the fastest parts within config/design.yaml; report files and optimum_params.yaml in design/
  feeder design --output design
  # parts at 15 mm/s with the least drive force
  feeder design --objective min-force --target-speed 0.015 --output design_min_force
  # a quick search for a part with more static friction, another seed
  feeder design --set static_friction=0.3 --generations 10 --seed 1"""


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
    parser.add_argument(
        "--seed", type=non_negative_int, default=0, help="optimiser seed, >= 0 (default 0)"
    )
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
        "--robust-generations",
        type=non_negative_int,
        default=10,
        metavar="N",
        help="generations of the robust search's evolution, 0: derate the nominal search's best "
        "designs only (default 10)",
    )
    parser.add_argument(
        "--map-points",
        type=int_at_least(2),
        default=15,
        help="speed-map grid points per axis, >= 2 (--output; default 15)",
    )
    parser.add_argument(
        "--output", type=output_path, metavar="DIR", help="write the report files here"
    )
    parser.add_argument(
        "--progress", action="store_true", help="show a progress bar even if stderr is not a TTY"
    )


def _load(args: argparse.Namespace) -> tuple[DesignConfig, FeederParameters, str]:
    from feeder_ros.design.space import load_design_config

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
    from feeder_ros.design.optimizer import (
        DesignProblem,
        evaluate_designs,
        optimize,
        population_size,
    )
    from feeder_ros.design.report import sensitivity_text, summary, write_report
    from feeder_ros.design.robust_search import robust_text
    from feeder_ros.design.robustness import assess, robustness_text
    from feeder_ros.design.sensitivity import sensitivity_table

    if args.objective == "min-force" and args.target_speed is None:
        raise CommandError("--objective min-force needs --target-speed (m/s)")
    if args.objective == "max-speed" and args.target_speed is not None:
        raise CommandError("--target-speed is for --objective min-force")
    check_output_dir(args.output, "--output", holds="report files (JSON, CSV, PNG, YAML)")
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
    bar = ProgressBar("design search", members * (args.generations + 1), show, unit="designs")

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
    built = assess(problem, result.params, design.tolerances)
    robust = _robust(problem, result, design, args.robust_generations, args.seed)
    # the robust optimum under the same draws: its margin per condition and largest tolerance
    robust_built = (
        None
        if robust is None or robust.best is None
        else assess(problem, robust.best.params, design.tolerances)
    )
    print(summary(result, reference, plant_label, args.seed))
    print(sensitivity_text(rows))
    print(robustness_text(built, design.tolerances))
    if robust is not None:
        print(robust_text(robust, problem, result.speed_mps))
    if robust_built is not None:
        print(robustness_text(robust_built, design.tolerances, "the robust design"))
        for line in robust_built.warnings:
            print(f"feeder design: warning: at the robust design, {line}", file=sys.stderr)
    for line in built.warnings:
        print(f"feeder design: warning: at the optimum, {line}", file=sys.stderr)
    if result.feasible and not built.robust:
        instead = (
            "; the robust design above holds its conditions (--output: robust_params.yaml)"
            if robust is not None and robust.best is not None
            else ""
        )
        print(
            f"feeder design: warning: the optimum meets every condition in only "
            f"{100 * built.all_met:.0f} % of the plants within the tolerances (a robust design: "
            f">= {100 * built.promised:g} %): it works near its nominal values only{instead}",
            file=sys.stderr,
        )
    if args.output is not None:
        written = write_report(
            Path(args.output),
            result,
            reference,
            rows,
            args.seed,
            args.map_points,
            built.record(),
            robust,
            None if robust_built is None else robust_built.record(),
        )
        for path in written:
            print(f"wrote {path}")
        finish_output_dir(Path(args.output), written)
    if not result.feasible:
        print(
            "feeder design: no evaluated design meets every condition; the least violating one is "
            "reported (widen the bounds, relax the conditions or search longer)",
            file=sys.stderr,
        )
        return 1
    return 0


def _robust(
    problem: DesignProblem,
    result: DesignResult,
    design: DesignConfig,
    generations: int,
    seed: int,
) -> RobustResult | None:
    """The robust search from the nominal search's best geometries (max-speed with the drive
    amplitude searched; else None, with a note)."""
    from feeder_ros.design.robust_search import robust_search

    if problem.objective != "max-speed" or "drive_amplitude_n" not in problem.space.names:
        print(
            "feeder design: note: the robust search covers max-speed with the drive amplitude "
            "searched; this search is nominal only (see the margin report)",
            file=sys.stderr,
        )
        return None
    return robust_search(
        problem, result.ranked, design.tolerances, generations=generations, seed=seed
    )


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
