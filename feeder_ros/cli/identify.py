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
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from feeder_ros.cli.arguments import non_negative_float, positive_float
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.progress import ProgressBar
from feeder_ros.cli.sim import (
    add_plant_arguments,
    atomic_text,
    default_config_path,
    plant_from_arguments,
)
from feeder_ros.identification.sweep import (
    SweepDataError,
    SweepGroup,
    SweepPlan,
    SweepPlanError,
    SweepResult,
    check_fit_data,
    parse_orders,
    parse_values,
)

if TYPE_CHECKING:
    from feeder_ros.identification.rational_fit import OrderScore

__all__ = ["HELP", "PLAN_NAME", "add_arguments", "default_plan_path", "run"]

HELP = "sweep the drive frequency (sim, live cell or bags) and fit a transfer function G(s)"
PLAN_NAME = "identify.yaml"
SOURCES = ("sim", "live", "bag", "csv")
MEASURES = ("sensors", "monitor", "truth")
DEFAULT_ORDERS = "0/2, 1/2, 1/3, 1/4, 2/4"
DEFAULT_FOLDS = 5
#: the paper's fit for its 31 g vehicle (Eq. 24), for the summary
PAPER_FIT_PERCENT = 63.0


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
    parser.add_argument("--source", choices=SOURCES, default="sim", help="where points come from")
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
        "--settle", type=non_negative_float, metavar="S", help="settle time per point"
    )
    group.add_argument(
        "--window", type=positive_float, metavar="S", help="measurement window per point"
    )
    group.add_argument(
        "--distance",
        type=positive_float,
        metavar="M",
        help="measure over this travel instead (0.085)",
    )
    group.add_argument(
        "--max-window", type=positive_float, metavar="S", help="distance mode: longest measurement"
    )
    group.add_argument(
        "--full-scale", type=positive_float, metavar="N", help="force at 100 %% amplitude"
    )
    group.add_argument(
        "--ramp-time", type=non_negative_float, metavar="S", help="live: ramp per step"
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
    add_plant_arguments(sim, "realistic")
    live = parser.add_argument_group("--source live: the cell")
    live.add_argument("--namespace", default="", help="the feeder's namespace, e.g. /cell/feeder_1")
    live.add_argument(
        "--measure",
        choices=MEASURES,
        default="sensors",
        help="sensors: part-sensor transits (the paper's timing); monitor: the speed monitor's "
        "estimated speed; truth: the simulator's part states",
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
    out.add_argument("--output", type=Path, metavar="DIR", help="sweep.csv, fit.json, fig9/10.png")
    out.add_argument("--model-out", type=Path, metavar="FILE.yaml", help="speed model file")
    out.add_argument(
        "--progress", action="store_true", help="show a progress bar even if stderr is not a TTY"
    )


# --------------------------------------------------------------------------------------- plan


@dataclass(frozen=True)
class FitSettings:
    orders: tuple[tuple[int, int], ...]
    min_speed_mps: float = 0.0
    folds: int = DEFAULT_FOLDS


def load_plan(args: argparse.Namespace) -> tuple[SweepPlan, FitSettings]:
    """The plan file (``--plan`` or the default) with the command-line overrides."""
    path = Path(args.plan) if args.plan is not None else default_plan_path()
    if not path.is_file():
        raise CommandError(f"--plan {path}: no such file")
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as error:
        raise CommandError(f"{path}: not valid YAML: {error}") from None
    if not isinstance(document, dict) or not isinstance(document.get("sweep"), dict):
        raise CommandError(f"{path}: expected a 'sweep:' mapping (and optionally 'fit:')")
    unknown = sorted(str(k) for k in document if k not in ("sweep", "fit"))
    if unknown:
        raise CommandError(f"{path}: unknown section(s) {', '.join(unknown)} (known: sweep, fit)")
    try:
        plan = SweepPlan.from_mapping(document["sweep"])
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
    bar = ProgressBar("sweeping (sim)", plan.point_count, show)
    try:
        result = offline_sweep(params, plan, progress=lambda done, total: bar.update(done))
    finally:
        bar.close()
    plant = {"config": str(config), "preset": preset, "parameters": params.as_dict()}
    return result, plant


def _sweep_live(args: argparse.Namespace, plan: SweepPlan, show: bool) -> SweepResult:
    try:
        from feeder_ros.nodes.sweep_client import LiveSweepError, run_live_sweep
    except ImportError as error:  # rclpy or the generated interfaces missing
        raise CommandError(
            f"--source live needs ROS 2 (rclpy) and the built interfaces: {error}"
        ) from None
    bar = ProgressBar("sweeping (live)", plan.point_count, show)
    try:
        return run_live_sweep(
            plan,
            namespace=args.namespace,
            measure=args.measure,
            manage_lifecycle=not args.no_lifecycle,
            progress=lambda done, total: bar.update(done),
            log=lambda text: _note(text, bar),
            use_sim_time=args.use_sim_time,
        )
    except LiveSweepError as error:
        raise CommandError(str(error)) from None
    finally:
        bar.close()


def _note(text: str, bar: ProgressBar) -> None:
    bar.relabel(bar.label)
    print(f"feeder identify: {text}", file=sys.stderr)


def _sweep_bag(args: argparse.Namespace, plan: SweepPlan, show: bool) -> SweepResult:
    from feeder_ros.bag.errors import BagError
    from feeder_ros.identification.bag_sweep import sweep_from_bags

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
            progress=report,
        )
    except BagError as error:
        raise CommandError(str(error)) from None
    finally:
        bar.close()
    sources = ", ".join(f"{n} from {name}" for name, n in swept.speed_sources().items())
    print(f"bag segments: {len(swept.result)} driven ({sources})")
    return swept.result


def _sweep_csv(args: argparse.Namespace) -> SweepResult:
    if len(args.inputs) != 1:
        raise CommandError("--source csv: give exactly one sweep CSV")
    return SweepResult.read_csv(args.inputs[0])


# ---------------------------------------------------------------------------------------- fit


@dataclass
class GroupFit:
    """The outcome for one (amplitude, mass) curve: the chosen order's scores, or why not."""

    group: SweepGroup
    scores: list[OrderScore] = field(default_factory=list)
    best: OrderScore | None = None
    peak_hz: float = math.nan
    left_out: list[str] = field(default_factory=list)
    error: str = ""

    @property
    def key(self) -> tuple[float, float]:
        return (self.group.amplitude_percent, self.group.part_mass_kg)


def fit_group(group: SweepGroup, settings: FitSettings) -> GroupFit:
    from feeder_ros.identification.rational_fit import (
        IdentificationError,
        best_order,
        compare_orders,
        min_distinct_frequencies,
    )

    def need(zeros: int, poles: int) -> int:  # the hold-out scheme of compare_orders decides
        return min_distinct_frequencies(zeros, poles, settings.folds)

    outcome = GroupFit(group)
    try:
        check_fit_data(
            group.frequency_hz,
            group.speed_mps,
            min(need(z, p) for z, p in settings.orders),
            what=group.label,
        )
    except SweepDataError as error:
        outcome.error = str(error)
        return outcome
    distinct = len(set(group.frequency_hz.tolist()))
    orders = []
    for zeros, poles in settings.orders:
        needed = need(zeros, poles)
        if distinct < needed:
            outcome.left_out.append(
                f"order {zeros}/{poles} needs {needed} frequencies for the hold-out check, "
                f"{distinct} usable"
            )
        else:
            orders.append((zeros, poles))
    try:
        outcome.scores = compare_orders(
            group.frequency_hz, group.speed_mps, group.amplitude_n, orders, folds=settings.folds
        )
        outcome.best = best_order(outcome.scores)
        lo, hi = float(group.frequency_hz.min()), float(group.frequency_hz.max())
        outcome.peak_hz = outcome.best.fit.model.peak_frequency_hz(lo, hi)
    except IdentificationError as error:
        outcome.error = f"{group.label}: {error}"
    return outcome


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
        raise CommandError(f"--model-out {path}: no fitted model to write")
    full_scale = result.full_scale_force_n
    if not math.isfinite(full_scale):
        raise CommandError(f"--model-out {path}: the sweep gives no drive full scale")
    save_speed_model(
        path, SpeedModelFile(full_scale, tuple(entries), f"feeder identify ({result.source})")
    )
    return len(entries)


# -------------------------------------------------------------------------------------- output


def summary(result: SweepResult, fits: Sequence[GroupFit], wall_s: float) -> str:
    lines = [
        f"sweep: {len(result)} points, {result.ok_count} usable, source {result.source} "
        f"({wall_s:.1f} s)"
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


def write_outputs(
    directory: Path,
    result: SweepResult,
    fits: Sequence[GroupFit],
    document: dict[str, Any] | None,
) -> list[Path]:
    from feeder_ros.identification.plots import plot_bode_magnitude, plot_speed_sweep

    directory.mkdir(parents=True, exist_ok=True)
    written = []
    with atomic_text(directory / "sweep.csv") as stream:
        result.write_csv(stream)
    written.append(directory / "sweep.csv")
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


def run(args: argparse.Namespace) -> int:
    if args.output is not None and args.output.exists() and not args.output.is_dir():
        raise CommandError(f"--output {args.output}: exists and is not a directory")
    if args.model_out is not None and args.no_fit:
        raise CommandError("--model-out needs the fit (drop --no-fit)")
    if args.source in ("sim", "live") and args.inputs:
        raise CommandError(f"--source {args.source} takes no input files ({args.inputs[0]})")
    plan: SweepPlan | None = None
    plan, settings = load_plan(args)
    show = bool(args.progress) or sys.stderr.isatty()
    started = time.perf_counter()
    plant: dict[str, Any] | None = None
    if args.source == "sim":
        result, plant = _sweep_sim(args, plan, show)
    elif args.source == "live":
        result = _sweep_live(args, plan, show)
    elif args.source == "bag":
        result = _sweep_bag(args, plan, show)
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
    if not args.no_fit and not any(f.best is not None for f in fits):
        raise CommandError(
            "no model could be fitted: " + "; ".join(f.error for f in fits if f.error)
        )
    if args.model_out is not None:
        count = write_model_file(args.model_out, result, fits)
        print(f"wrote the speed model ({count} entries) to {args.model_out}")
    return 0
