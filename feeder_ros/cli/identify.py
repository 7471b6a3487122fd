"""``feeder identify``: speed sweep (paper Fig. 9) and fit of G(s) to it (Eqs. 21-25, Fig. 10).

The sweep comes from one of four sources behind one result type
(:class:`~feeder_ros.identification.sweep.SweepResult`):

* ``sim``: the physics core offline, all points in parallel
  (:mod:`feeder_ros.identification.offline_sweep`); the plant from the simulator YAML like
  ``feeder sim`` (``--config``, ``--preset``, ``--set``), by default its ``realistic`` preset;
* ``live``: a running cell (simulated or real) through the drive interface's services and the
  part sensors or speed monitor (:mod:`feeder_ros.nodes.sweep_client`);
* ``bag``: recorded bags of a sweep (:mod:`feeder_ros.identification.bag_sweep`);
* ``csv``: a ``sweep.csv`` written earlier, fitted again.

The plan (frequencies, amplitudes, part masses, settle time, window or distance) is
``config/identify.yaml`` (``--plan``) with command-line overrides. Per (amplitude, part mass) the
rational models of ``--orders`` are fitted (:mod:`feeder_ros.identification.rational_fit`), scored
on all data and on held-out frequencies, and the best is kept: fit %, poles, zeros, peak frequency.
``--output DIR`` writes ``sweep.csv``, ``fit.json``, ``fig9.png`` and ``fig10.png``; ``--model-out``
the speed model file the drive interface loads for its target-speed mode.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from feeder_ros.cli.arguments import non_negative_float, positive_float
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.outputs import (
    check_apart_from_inputs,
    check_output_dir,
    check_output_file,
    finish_output_dir,
    output_path,
)
from feeder_ros.cli.progress import ProgressBar
from feeder_ros.cli.sim import add_plant_arguments, default_config_path, plant_from_arguments
from feeder_ros.yaml_files import YamlFileError, read_yaml

# the sweep, fit and report modules (scipy, matplotlib) are imported where they are used, so
# that ``feeder --help`` does not load them
if TYPE_CHECKING:
    from feeder_ros.bag.analysis import BagAnalysis
    from feeder_ros.identification.group_fit import FitSettings, GroupFit
    from feeder_ros.identification.sweep import SweepPlan, SweepResult

__all__ = ["EPILOG", "HELP", "PLAN_NAME", "add_arguments", "default_plan_path", "run"]

HELP = "sweep the drive frequency (sim, live cell or bags) and fit a transfer function G(s)"
EPILOG = (
    "exit status: 0 done; 1 --source bag and some bag lost recorded data (corrupt chunks, "
    "missing split files, ...): its points come from what could be read, and every output is "
    "written all the same; 2 bad input, or no usable point or model. "
    "Ctrl-C cuts a sweep short: exit status 130 (a live sweep with --output saves the points "
    "measured so far first)"
    """

examples:
  # the plan of config/identify.yaml on the simulator: sweep.csv, fit.json, Fig. 9/10 in sweep/
  feeder identify --output sweep
  # a coarser grid at 40 %, and the speed model file the drive interface loads
  feeder identify --frequencies 19:27:1 --amplitudes 40 --model-out speed_model.yaml
  # the running demo cell's feeder (its 50 g parts), timed by its part sensors
  feeder identify --source live --namespace /demo_cell/feeder_1 --masses 0.05 --output live
  # the measured points fitted again, with other model orders
  feeder identify --source csv sweep/sweep.csv --orders 1/2,1/3"""
)
PLAN_NAME = "identify.yaml"
SOURCES = ("sim", "live", "bag", "csv")
MEASURES = ("sensors", "monitor", "truth")
DEFAULT_ORDERS = "0/2, 1/2, 1/3, 1/4, 2/4"
SIM_PRESET = "realistic"  #: --source sim: the simulator YAML section of the plant by default


def default_plan_path() -> Path:
    """``identify.yaml`` beside the simulator YAML (source tree or installed share directory)."""
    return default_config_path().parent / PLAN_NAME


# ------------------------------------------------------------------------------------ options


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "inputs",
        nargs="*",
        type=Path,
        metavar="INPUT",
        help="--source bag: bag directories or .mcap files; --source csv: one sweep.csv",
    )
    parser.add_argument(
        "--source", choices=SOURCES, default="sim", help="where points come from (default sim)"
    )
    parser.add_argument(
        "--plan", type=Path, metavar="YAML", help=f"sweep plan and fit settings ({PLAN_NAME})"
    )

    group = parser.add_argument_group("plan overrides")
    group.add_argument(
        "--frequencies",
        metavar="LIST",
        help="Hz: numbers and start:stop:step ranges, e.g. 38:58:0.5",
    )
    group.add_argument("--amplitudes", metavar="LIST", help="percent of full scale, e.g. 35:47:2")
    group.add_argument("--masses", metavar="LIST", help="part masses in kg, e.g. 0.031,0.06")
    group.add_argument(
        "--settle", type=non_negative_float, metavar="S", help="settle time per point [s]"
    )
    group.add_argument(
        "--window", type=positive_float, metavar="S", help="measurement window per point [s]"
    )
    group.add_argument(
        "--distance",
        type=positive_float,
        metavar="M",
        help="measure over this travel instead [m] (the paper's 0.085)",
    )
    group.add_argument(
        "--max-window",
        type=positive_float,
        metavar="S",
        help="distance mode: longest measurement [s]",
    )
    group.add_argument(
        "--full-scale", type=positive_float, metavar="NEWTON", help="force at 100 %% amplitude [N]"
    )
    group.add_argument(
        "--ramp-time", type=non_negative_float, metavar="S", help="live: ramp per step [s]"
    )
    fit = parser.add_argument_group("fit")
    fit.add_argument(
        "--orders", metavar="Z/P,...", help=f"model orders zeros/poles (default {DEFAULT_ORDERS})"
    )
    fit.add_argument(
        "--min-speed",
        type=non_negative_float,
        metavar="M/S",
        help="fit only points faster than this (default 0: parts moving forward)",
    )
    fit.add_argument("--no-fit", action="store_true", help="measure (and write) the sweep only")
    sim = parser.add_argument_group("--source sim: the plant")
    add_plant_arguments(sim, SIM_PRESET)
    live = parser.add_argument_group("--source live: the cell")
    live.add_argument(
        "--namespace",
        default="",
        help="the feeder's namespace, e.g. /cell/feeder_1 (--source bag too: the feeder of bags "
        "that hold several)",
    )
    live.add_argument(
        "--measure",
        choices=MEASURES,
        help="sensors (default): part-sensor transits (the paper's timing); monitor: the speed "
        "monitor's estimated speed; truth: the simulator's part states",
    )
    live.add_argument(
        "--use-sim-time",
        action="store_true",
        help="time settle and windows on the cell's /clock (a simulator with use_sim_time)",
    )
    live.add_argument(
        "--no-lifecycle",
        action="store_true",
        help="do not configure/activate the drive interface (it must be active)",
    )
    out = parser.add_argument_group("output")
    out.add_argument(
        "--output", type=output_path, metavar="DIR", help="sweep.csv, fit.json, fig9/10.png"
    )
    out.add_argument("--model-out", type=output_path, metavar="FILE.yaml", help="speed model file")
    out.add_argument(
        "--progress", action="store_true", help="show a progress bar even if stderr is not a TTY"
    )


# --------------------------------------------------------------------------------------- plan


def load_plan(args: argparse.Namespace) -> tuple[SweepPlan, FitSettings]:
    """The plan file (``--plan`` or the default) with the command-line overrides."""
    from feeder_ros.identification.group_fit import DEFAULT_FOLDS, FitSettings
    from feeder_ros.identification.sweep import (
        SweepPlan,
        SweepPlanError,
        parse_orders,
        parse_values,
    )

    path = Path(args.plan) if args.plan is not None else default_plan_path()
    if not path.is_file():
        raise CommandError(f"--plan {path}: no such file")
    try:
        document = read_yaml(path)
    except YamlFileError as error:
        raise CommandError(str(error)) from None
    if not isinstance(document, dict) or not isinstance(document.get("sweep"), dict):
        raise CommandError(f"{path}: expected a 'sweep:' mapping (and optionally 'fit:')")
    unknown = sorted(str(k) for k in document if k not in ("sweep", "fit"))
    if unknown:
        raise CommandError(f"{path}: unknown section(s) {', '.join(unknown)} (known: sweep, fit)")
    sweep = dict(document["sweep"])
    # the grid the command line gives completes a plan file without it (and overrides it below)
    for name, flag, value in (
        ("frequencies_hz", "--frequencies", args.frequencies),
        ("amplitudes_percent", "--amplitudes", args.amplitudes),
        ("part_masses_kg", "--masses", args.masses),
    ):
        if value is not None and name not in sweep:
            try:
                sweep[name] = list(parse_values(name, value))
            except SweepPlanError as error:
                raise CommandError(f"{flag}: {error}") from None
    try:
        plan = SweepPlan.from_mapping(sweep)
    except SweepPlanError as error:
        raise CommandError(f"{path}: sweep.{error}") from None
    fit_section = document.get("fit") or {}
    if not isinstance(fit_section, dict):
        raise CommandError(f"{path}: 'fit:' must be a mapping")
    unknown = sorted(str(k) for k in fit_section if k not in ("orders", "min_speed_mps", "folds"))
    if unknown:
        raise CommandError(
            f"{path}: fit.{unknown[0]}: unknown (known: orders, min_speed_mps, folds)"
        )
    try:
        orders = parse_orders(fit_section.get("orders", DEFAULT_ORDERS))
    except SweepPlanError as error:
        raise CommandError(f"{path}: fit.{error}") from None
    min_speed = fit_section.get("min_speed_mps", 0.0)
    folds = fit_section.get("folds", DEFAULT_FOLDS)
    if isinstance(min_speed, bool) or not isinstance(min_speed, int | float):
        raise CommandError(f"{path}: fit.min_speed_mps={min_speed!r} is not a number")
    if not (math.isfinite(min_speed) and min_speed >= 0.0):
        raise CommandError(f"{path}: fit.min_speed_mps={min_speed!r} must be >= 0 and finite")
    if isinstance(folds, bool) or not isinstance(folds, int) or folds < 2:
        raise CommandError(f"{path}: fit.folds={folds!r} must be an integer >= 2")

    overrides: dict[str, Any] = {
        name: value
        for name, value in (
            ("frequencies_hz", args.frequencies),
            ("amplitudes_percent", args.amplitudes),
            ("part_masses_kg", args.masses),
            ("settle_s", args.settle),
            ("window_s", args.window),
            ("distance_m", args.distance),
            ("max_window_s", args.max_window),
            ("full_scale_force_n", args.full_scale),
            ("ramp_time_s", args.ramp_time),
        )
        if value is not None
    }
    if args.window is not None and args.distance is not None:
        raise CommandError("--window and --distance: give one (a window or a distance)")
    try:
        plan = SweepPlan.from_mapping(overrides, base=plan)
        if args.orders is not None:
            orders = parse_orders(args.orders)
    except SweepPlanError as error:
        flag = {
            "frequencies_hz": "--frequencies",
            "amplitudes_percent": "--amplitudes",
            "part_masses_kg": "--masses",
            "orders": "--orders",
        }.get(error.name, error.name)
        raise CommandError(f"{flag}: {error}") from None
    if args.min_speed is not None:
        min_speed = args.min_speed
    return plan, FitSettings(orders, float(min_speed), int(folds))


# ------------------------------------------------------------------------------------ sources


def _sweep_sim(
    args: argparse.Namespace, plan: SweepPlan, show: bool
) -> tuple[SweepResult, dict[str, Any]]:
    from feeder_ros.identification.offline_sweep import offline_sweep

    params, config, preset = plant_from_arguments(args)
    bar = ProgressBar("sweeping (sim)", plan.point_count, show, unit="points")
    try:
        result = offline_sweep(params, plan, progress=lambda done, total: bar.update(done))
    finally:
        bar.close()
    plant = {"config": str(config), "preset": preset, "parameters": params.as_dict()}
    return result, plant


def _sweep_live(args: argparse.Namespace, plan: SweepPlan, show: bool) -> SweepResult:
    from feeder_ros.identification.report import write_points

    try:
        from feeder_ros.nodes.sweep_client import LiveSweepError, run_live_sweep
    except ImportError as error:  # rclpy or the generated interfaces missing
        raise CommandError(
            f"--source live needs ROS 2 (rclpy) and the built interfaces: {error}"
        ) from None
    bar = ProgressBar("sweeping (live)", plan.point_count, show, unit="points")

    def save(result: SweepResult) -> None:
        # before the client's teardown, which can hang in the middleware (then the process ends
        # with status 1 and these points are what is left of the sweep); a sweep cut short by an
        # error or Ctrl-C keeps the points measured until then
        if args.output is not None:
            path = write_points(args.output, result)
            count = len(result.points)
            if count == plan.point_count:
                _note(f"measured points saved to {path}", bar)
            else:
                _note(
                    f"{count} of {plan.point_count} points measured, saved to {path} (fit them "
                    f"with: feeder identify --source csv {path})",
                    bar,
                )

    try:
        return run_live_sweep(
            plan,
            namespace=args.namespace,
            measure=args.measure or "sensors",
            manage_lifecycle=not args.no_lifecycle,
            progress=lambda done, total: bar.update(done),
            log=lambda text: _note(text, bar),
            use_sim_time=args.use_sim_time,
            measured=save,
        )
    except LiveSweepError as error:
        raise CommandError(str(error)) from None
    finally:
        bar.close()


def _note(text: str, bar: ProgressBar) -> None:
    bar.relabel(bar.label)
    print(f"feeder identify: {text}", file=sys.stderr)


def _sweep_bag(args: argparse.Namespace, plan: SweepPlan, show: bool) -> tuple[SweepResult, int]:
    """The sweep measured in the bags, and how many of them lost recorded data."""
    from feeder_ros.bag.errors import BagError
    from feeder_ros.identification.bag_sweep import sweep_from_bags
    from feeder_ros.identification.sweep import parse_values

    if not args.inputs:
        raise CommandError("--source bag: give the bag(s) of the sweep")
    # --masses in the order of the bags (the plan sorts its masses)
    masses = (
        parse_values("part_masses_kg", args.masses)
        if args.masses is not None
        else plan.part_masses_kg
    )
    if len(masses) not in (1, len(args.inputs)):
        raise CommandError(
            f"{len(masses)} part masses ({', '.join(f'{m:g}' for m in masses)} kg) for "
            f"{len(args.inputs)} bag(s): give --masses with one mass for all bags or one per bag "
            "(in the order of the bags)"
        )
    bar = ProgressBar(str(args.inputs[0]), 1.0, show)

    def report(index: int, fraction: float) -> None:
        if str(args.inputs[index]) != bar.label:
            bar.relabel(str(args.inputs[index]))
        bar.update(fraction)

    try:
        swept = sweep_from_bags(
            args.inputs,
            full_scale_force_n=plan.full_scale_force_n,
            part_masses_kg=masses,
            min_duration_s=plan.window_s if plan.window_s is not None else 0.5,
            namespace=args.namespace or None,
            progress=report,
        )
    except BagError as error:
        raise CommandError(str(error)) from None
    finally:
        bar.close()
    sources = ", ".join(f"{n} from {name}" for name, n in swept.speed_sources().items())
    print(f"bag segments: {len(swept.result)} driven ({sources})")
    for analysis in swept.analyses:
        _report_bag_problems(analysis)
    return swept.result, sum(1 for a in swept.analyses if a.data_lost)


#: problems listed per bag on stderr (the rest are counted)
_MAX_PROBLEMS_SHOWN = 10


def _report_bag_problems(analysis: BagAnalysis) -> None:
    """What the bag reader worked around, on stderr: the points come from what could be read."""
    where = f"feeder identify: {analysis.path}"
    if analysis.data_lost:
        print(
            f"{where}: warning: data lost ({analysis.loss_summary()}): its segments are measured "
            "on what could be read",
            file=sys.stderr,
        )
    if analysis.cut_short:
        print(f"{where}: warning: cut short (the recorder did not close the bag)", file=sys.stderr)
    for problem in analysis.problems[:_MAX_PROBLEMS_SHOWN]:
        print(f"{where}: problem: {problem}", file=sys.stderr)
    if len(analysis.problems) > _MAX_PROBLEMS_SHOWN:
        more = len(analysis.problems) - _MAX_PROBLEMS_SHOWN
        print(f"{where}: ... and {more} more problem(s)", file=sys.stderr)


def _sweep_csv(args: argparse.Namespace) -> SweepResult:
    if len(args.inputs) != 1:
        raise CommandError("--source csv: give exactly one sweep CSV")
    from feeder_ros.identification.sweep import SweepResult

    return SweepResult.read_csv(args.inputs[0])


def run(args: argparse.Namespace) -> int:
    from feeder_ros.identification.group_fit import fit_group
    from feeder_ros.identification.report import fit_json, summary, write_model_file, write_outputs

    if args.source == "bag":
        check_apart_from_inputs(args.output, "--output", args.inputs)
    check_output_dir(args.output, "--output", holds="sweep and fit files (CSV, JSON, PNG)")
    check_output_file(
        args.model_out,
        "--model-out",
        by_name="the drive interface loads the speed model from a file (speed_model_file)",
    )
    if args.model_out is not None and args.no_fit:
        raise CommandError("--model-out needs the fit (drop --no-fit)")
    if args.source in ("sim", "live") and args.inputs:
        raise CommandError(f"--source {args.source} takes no input files ({args.inputs[0]})")
    if args.source != "live":
        for flag, given in (
            ("--namespace", bool(args.namespace)),
            ("--measure", args.measure is not None),
            ("--use-sim-time", args.use_sim_time),
            ("--no-lifecycle", args.no_lifecycle),
        ):
            if given:
                raise CommandError(f"{flag} is for --source live (not {args.source})")
    if args.source != "sim":
        for flag, given in (
            ("--config", args.config is not None),
            ("--preset", args.preset != SIM_PRESET),
            ("--set", bool(args.overrides)),
        ):
            if given:
                raise CommandError(
                    f"{flag} is for --source sim (the simulated plant), not {args.source}"
                )
    plan: SweepPlan | None = None
    plan, settings = load_plan(args)
    show = bool(args.progress) or sys.stderr.isatty()
    started = time.perf_counter()
    plant: dict[str, Any] | None = None
    lost_bags = 0  # bags that lost recorded data (their points measured on what was read)
    if args.source == "sim":
        result, plant = _sweep_sim(args, plan, show)
    elif args.source == "live":
        result = _sweep_live(args, plan, show)
    elif args.source == "bag":
        result, lost_bags = _sweep_bag(args, plan, show)
    else:
        result = _sweep_csv(args)
        plan = None  # the CSV's points are what was measured; the plan file does not apply
    if result.ok_count == 0:
        reasons = sorted({p.reason for p in result.points if not p.ok})
        raise CommandError(f"no usable point in the sweep ({'; '.join(reasons)[:500]})")

    fits: list[GroupFit] = []
    if not args.no_fit:
        groups = result.groups(settings.min_speed_mps)
        bar = ProgressBar("fitting", len(groups), show)
        try:
            for k, group in enumerate(groups):
                fits.append(fit_group(group, settings))
                bar.update(k + 1)
        finally:
            bar.close()
    wall = time.perf_counter() - started
    document = None if args.no_fit else fit_json(result, fits, plan, settings, plant)
    print(summary(result, fits, wall))
    if args.output is not None:
        written = write_outputs(args.output, result, fits, document)
        print(f"wrote {', '.join(p.name for p in written)} to {args.output}")
        finish_output_dir(args.output, written)
    if not args.no_fit and not any(f.best is not None for f in fits):
        raise CommandError(
            "no model could be fitted: " + "; ".join(f.error for f in fits if f.error)
        )
    if args.model_out is not None:
        count = write_model_file(args.model_out, result, fits)
        print(f"wrote the speed model ({count} entries) to {args.model_out}")
    if lost_bags:
        print(
            f"feeder identify: data lost in {lost_bags} bag(s) (see above): the sweep and its "
            "fit come from what could be read",
            file=sys.stderr,
        )
        return 1
    return 0
