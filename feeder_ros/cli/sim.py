"""``feeder sim``: simulate the feeder offline and write CSV, events and figures.

Parameters come from the simulator's YAML file (``config/platform_simulator.yaml``, ROS
``ros__parameters`` form), then ``--set name=value`` overrides (validated by
:func:`~feeder_ros.physics.parameters.parse_parameter_value`). Samples are written at exact
multiples of ``1/--rate``. Output files are written to a temporary file beside the target and
renamed, so a failed or interrupted run never leaves a half-written file. The CSVs (``--output``,
``--events``) may go to standard output (``-`` or ``/dev/stdout``; the summary is then printed on
standard error), to standard error (``/dev/stderr``), a FIFO or a device (written in place); the
figures (``--plot DIR``) need a directory (:mod:`feeder_ros.cli.outputs`).
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from feeder_ros.cli.arguments import non_negative_int, positive_float
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.outputs import (
    check_output_dir,
    check_output_file,
    finish_output_dir,
    open_output_text,
    output_path,
    report_stream,
)
from feeder_ros.cli.progress import ProgressBar
from feeder_ros.nodes.platform_simulator_parameters import NODE_PARAMETERS
from feeder_ros.physics.parameters import FeederParameters, ParameterError, parse_parameter_value
from feeder_ros.physics.run_checks import likely_unit_mistakes, no_slip_note
from feeder_ros.yaml_files import YamlFileError, read_yaml

if TYPE_CHECKING:
    from feeder_ros.physics.simulation import PartSpec, SimulationResult

__all__ = [
    "CONFIG_NAME",
    "EPILOG",
    "HELP",
    "NODE_NAME",
    "NON_MODEL_KEYS",
    "NO_PRESET",
    "add_arguments",
    "add_plant_arguments",
    "default_config_path",
    "load_parameters",
    "plant_from_arguments",
    "run",
]

HELP = "simulate the feeder offline (exact event-driven engine) and write CSV/events/figures"
EPILOG = """\
Ctrl-C cuts the run short: exit status 130, no output file half-written.

examples:
  # 2 s of the paper's case study with 3 parts: samples and events as CSV
  feeder sim --duration 2 --parts 3 --output run.csv --events events.csv
  # the damped plant at 40 N drive amplitude, Fig. 8-style figures into figures/
  feeder sim --preset realistic --set drive_amplitude_n=40 --plot figures
  # the samples on stdout (the summary goes to stderr)
  feeder sim --duration 0.5 --output - | head -3"""
NODE_NAME = "platform_simulator"
CONFIG_NAME = "platform_simulator.yaml"
# ROS parameters of the simulator node that are not model parameters: accepted in the YAML, ignored.
NON_MODEL_KEYS: frozenset[str] = frozenset(NODE_PARAMETERS)
_PACKAGE = "feeder_ros"


def default_config_path() -> Path:
    """The simulator YAML: the source tree's ``config/`` when run from a checkout, else the
    installed share directory (ament index, then ``<prefix>/share/feeder_ros/config``)."""
    source = Path(__file__).resolve().parents[2] / "config" / CONFIG_NAME
    if source.is_file():
        return source
    candidates: list[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory(_PACKAGE)) / "config" / CONFIG_NAME)
    except Exception:
        pass
    candidates.append(Path(sys.prefix) / "share" / _PACKAGE / "config" / CONFIG_NAME)
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise CommandError(
        f"cannot find {CONFIG_NAME} (looked in {source.parent} and the installed share "
        "directory); pass --config FILE"
    )


def load_parameters(
    path: Path, overrides: Sequence[str] = (), preset: str | None = None
) -> FeederParameters:
    """Model parameters from a ROS parameter YAML file plus ``name=value`` overrides.

    ``preset`` picks the section ``platform_simulator_<preset>`` (e.g. ``realistic``) instead of
    ``platform_simulator``.
    """
    node_name = NODE_NAME if preset is None else f"{NODE_NAME}_{preset}"
    try:
        document = read_yaml(path)
    except YamlFileError as error:
        raise CommandError(str(error)) from None
    section: Any = None
    if isinstance(document, Mapping):
        keys: tuple[str, ...] = (node_name, f"/{node_name}", f"/**/{node_name}")
        if not preset:
            keys += ("/**",)
        for key in keys:
            if key in document:
                section = document[key]
                break
    if not isinstance(section, Mapping) or not isinstance(section.get("ros__parameters"), Mapping):
        presets = sorted(
            str(key).rsplit("/", 1)[-1][len(NODE_NAME) + 1 :]
            for key in (document if isinstance(document, Mapping) else {})
            if str(key).rsplit("/", 1)[-1].startswith(f"{NODE_NAME}_")
        )
        known = f" (presets in this file: {', '.join(presets) or 'none'})" if preset else ""
        raise CommandError(
            f"{path}: expected '{node_name}: ros__parameters: {{name: value}}'{known}"
        )
    values = {k: v for k, v in section["ros__parameters"].items() if k not in NON_MODEL_KEYS}
    try:
        params = FeederParameters.from_mapping(values)
    except ParameterError as error:
        raise CommandError(f"{path}: {error}") from None
    changes: dict[str, float | int | str] = {}
    for item in overrides:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise CommandError(f"--set {item!r}: expected name=value")
        changes[name.strip()] = parse_parameter_value(name.strip(), text.strip())
    return params.with_changes(**changes) if changes else params


NO_PRESET = "none"  #: --preset value for the YAML's base section (the paper's undamped case)


def add_plant_arguments(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    default_preset: str | None,
    set_help: str = "override one model parameter (repeatable), e.g. --set drive_amplitude_n=40",
) -> None:
    """``--config``, ``--preset`` and ``--set NAME=VALUE``: the plant, as ``feeder sim`` reads it
    (shared by every sub-command that simulates)."""
    parser.add_argument("--config", type=Path, help=f"simulator YAML (default: {CONFIG_NAME})")
    base = (
        f"default '{default_preset}'; '{NO_PRESET}': the base section, the paper's undamped case"
        if default_preset
        else "default: the base section, the paper's undamped case study"
    )
    parser.add_argument(
        "--preset",
        default=default_preset,
        help="use the YAML's platform_simulator_<PRESET> section, e.g. 'realistic' (damped); "
        + base,
    )
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE", help=set_help
    )


def plant_from_arguments(args: argparse.Namespace) -> tuple[FeederParameters, Path, str | None]:
    """The plant of :func:`add_plant_arguments`' options: (parameters, YAML path, preset)."""
    config = Path(args.config) if args.config is not None else default_config_path()
    if not config.is_file():
        raise CommandError(f"--config {config}: no such file")
    preset = None if args.preset in (None, "", NO_PRESET) else str(args.preset)
    return load_parameters(config, args.overrides, preset), config, preset


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_plant_arguments(parser, None)
    parser.add_argument(
        "--duration", type=positive_float, default=1.0, help="simulated time in s (default 1)"
    )
    parser.add_argument(
        "--rate",
        type=positive_float,
        default=1000.0,
        help="output samples per second; samples at exact multiples of 1/rate (default 1000)",
    )
    parser.add_argument(
        "--parts", type=non_negative_int, default=1, help="number of parts on the track (default 1)"
    )
    parser.add_argument(
        "--output", type=output_path, help="write the samples to this CSV file ('-': stdout)"
    )
    parser.add_argument(
        "--events",
        type=output_path,
        help="write the events (t_s,kind,part) to this CSV ('-': stdout)",
    )
    parser.add_argument(
        "--plot", type=output_path, metavar="DIR", help="write the figures (PNG) here"
    )
    parser.add_argument(
        "--progress", action="store_true", help="show a progress bar even if stderr is not a TTY"
    )


def samples_header(n_parts: int) -> list[str]:
    header = ["t_s", "carrier_x_m", "carrier_v_mps", "carrier_a_mps2", "branch"]
    for i in range(n_parts):
        header += [f"part{i}_x_m", f"part{i}_v_mps", f"part{i}_phase"]
    return header


def write_samples(stream: TextIO, result: SimulationResult) -> None:
    n_parts = int(result.part_x_m.shape[1]) if result.part_x_m.ndim == 2 else 0
    writer = csv.writer(stream, lineterminator="\n")
    writer.writerow(samples_header(n_parts))
    rows = len(result.t_s)
    chunk = 20000
    for start in range(0, rows, chunk):
        stop = min(start + chunk, rows)
        buffer = io.StringIO()
        for k in range(start, stop):
            row = [
                repr(float(result.t_s[k])),
                repr(float(result.carrier_x_m[k])),
                repr(float(result.carrier_v_mps[k])),
                repr(float(result.carrier_a_mps2[k])),
                str(int(result.branch[k])),
            ]
            for i in range(n_parts):
                row += [
                    repr(float(result.part_x_m[k, i])),
                    repr(float(result.part_v_mps[k, i])),
                    str(int(result.part_phase[k, i])),
                ]
            buffer.write(",".join(row) + "\n")
        stream.write(buffer.getvalue())


def write_events(stream: TextIO, result: SimulationResult) -> None:
    from feeder_ros.physics.simulation import EventKind

    writer = csv.writer(stream, lineterminator="\n")
    writer.writerow(["t_s", "kind", "part"])
    for t, kind, part in zip(result.event_t_s, result.event_kind, result.event_part, strict=True):
        writer.writerow([repr(float(t)), EventKind(int(kind)).name, int(part)])


def default_parts(params: FeederParameters, count: int) -> tuple[PartSpec, ...]:
    """``count`` parts of the configured kind, spread over the first half of the track."""
    from feeder_ros.physics.simulation import PartSpec

    spacing = 0.5 * params.track_length_m / max(count, 1)
    return tuple(PartSpec(position_m=i * spacing) for i in range(count))


def _check_sample_memory(duration_s: float, rate_hz: float, parts: int) -> None:
    """Refuse a run whose samples alone would not fit in this machine's memory (numpy would fail
    with MemoryError after the simulation started)."""
    samples = math.floor(duration_s * rate_hz * (1.0 + 1e-12)) + 1
    # time, carrier x, v, a (float64) and branch (int8); per part x, v (float64) and phase (int8);
    # twice: chunks and their concatenation, or the arrays and the CSV's formatting
    need = 2.0 * samples * (8 * 4 + 1 + parts * 17)
    try:
        memory = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not on this platform: no check
        return
    if need > memory:
        raise CommandError(
            f"--duration {duration_s:g} s at --rate {rate_hz:g} /s is {samples:,} samples "
            f"({need / 2**30:.3g} GiB with {parts} part(s)), more than this machine's memory "
            f"({memory / 2**30:.3g} GiB): lower --rate or --duration"
        )


def simulate_with_progress(
    params: FeederParameters,
    duration_s: float,
    rate_hz: float,
    parts: tuple[PartSpec, ...],
    progress: ProgressBar,
) -> SimulationResult:
    """``simulate``, in chunks of the exact simulator when a progress bar is shown.

    Chunked advancing gives exactly the same trajectory as one run (``FeederSimulator``).
    """
    from feeder_ros.physics.simulation import FeederSimulator, simulate

    if not progress.enabled or params.stiffness_model != "sharp":
        progress.update(0.0)
        result = simulate(params, duration_s, rate_hz, parts=parts)
        progress.update(duration_s)
        return result
    n = math.floor(duration_s * rate_hz * (1.0 + 1e-12))
    samples = np.arange(n + 1, dtype=np.float64) / rate_hz
    simulator = FeederSimulator(params, parts)
    chunks: list[SimulationResult] = []
    pieces = 50
    for k in range(1, pieces + 1):
        t_end = duration_s * k / pieces if k < pieces else duration_s
        lo = int(np.searchsorted(samples, simulator.time_s, side="left"))
        hi = int(np.searchsorted(samples, t_end, side="left" if k < pieces else "right"))
        chunks.append(simulator.advance(t_end, samples[lo:hi]))
        progress.update(t_end)
    return _concatenate(chunks)


def _concatenate(chunks: Sequence[SimulationResult]) -> SimulationResult:
    """One result from consecutive ``FeederSimulator.advance`` chunks (totals from the last)."""
    from dataclasses import replace

    from feeder_ros.physics.simulation import EventLog

    last = chunks[-1]
    return replace(
        last,
        **{
            name: np.concatenate([getattr(chunk, name) for chunk in chunks])
            for name in (
                "t_s",
                "carrier_x_m",
                "carrier_v_mps",
                "carrier_a_mps2",
                "branch",
                "part_x_m",
                "part_v_mps",
                "part_phase",
            )
        },
        events=EventLog([chunk.events.arrays() for chunk in chunks]),
    )


def run(args: argparse.Namespace) -> int:
    check_output_file(args.output, "--output")
    check_output_file(args.events, "--events")
    check_output_dir(args.plot, "--plot", holds="figures (PNG files)")
    report = report_stream([("--output", args.output), ("--events", args.events)])
    params, _, _ = plant_from_arguments(args)
    parts = default_parts(params, args.parts)
    for warning in likely_unit_mistakes(params, args.rate):
        print(f"feeder sim: warning: {warning}", file=sys.stderr)
    _check_sample_memory(args.duration, args.rate, len(parts))
    show = bool(args.progress) or (sys.stderr.isatty() and args.duration >= 10.0)
    progress = ProgressBar("simulating", args.duration, show, unit="sim s")
    warmup = _warm_up(params)
    started = time.perf_counter()
    try:
        result = simulate_with_progress(params, args.duration, args.rate, parts, progress)
    finally:
        progress.close()
    wall = time.perf_counter() - started

    if args.output is not None:
        with open_output_text(args.output) as stream:
            write_samples(stream, result)
    if args.events is not None:
        with open_output_text(args.events) as stream:
            write_events(stream, result)
    figures: list[Path] = []
    if args.plot is not None:
        from feeder_ros.physics.case_study import DETAIL_WINDOW_S, detail_run, plot_result

        detail = detail_run(
            params, parts or default_parts(params, 1), min(DETAIL_WINDOW_S, args.duration)
        )
        figures = plot_result(result, params, Path(args.plot), detail=detail)
        finish_output_dir(Path(args.plot), figures, report)

    print(summary(params, result, args.duration, wall, figures, warmup), file=report)
    return 0


def _warm_up(params: FeederParameters) -> float:
    """Compile (or load from numba's cache) the exact engine's kernels before timing the run."""
    if params.stiffness_model != "sharp":
        return 0.0
    from feeder_ros.physics.simulation import simulate

    started = time.perf_counter()
    simulate(params, 1e-3, 1e3, parts=())
    return time.perf_counter() - started


def summary(
    params: FeederParameters,
    result: SimulationResult,
    duration_s: float,
    wall_s: float,
    figures: Sequence[Path] = (),
    warmup_s: float = 0.0,
) -> str:
    from feeder_ros.physics.case_study import case_study_facts_from_result

    facts = case_study_facts_from_result(params, result)
    n_parts = int(result.part_x_m.shape[1]) if result.part_x_m.ndim == 2 else 0
    lines = [
        f"simulated {duration_s:g} s ({params.stiffness_model} model, "
        f"{params.stiffness_switch} switch, A = {params.drive_amplitude_n:g} N, "
        f"f_d = {params.drive_frequency_hz:g} Hz, c = {params.damping_ns_per_m:g} N*s/m)",
        f"natural frequencies: forward {facts.forward_natural_frequency_hz:.2f} Hz, "
        f"backward {facts.backward_natural_frequency_hz:.2f} Hz",
    ]
    if n_parts:
        speed = float(np.nanmean(result.mean_part_speed_mps()))
        slip = float(np.nanmean(result.slip_fraction()))
        onset = facts.first_slip_onset_s
        lines += [
            f"parts: {n_parts} ({result.exited_count()} left the track), mean part speed "
            f"{speed * 1e3:.4g} mm/s, slip fraction {slip:.3f}, "
            + (f"part 0 first slips at {onset * 1e3:.3f} ms" if onset is not None else "no slip"),
        ]
        if onset is None and slip == 0.0:
            lines.append(no_slip_note(params, result.carrier_a_mps2))
    lines += [
        f"events: {len(result.event_t_s)}",
        f"simulation wall time {wall_s:.3g} s, real-time factor "
        f"{duration_s / wall_s if wall_s > 0 else math.inf:.1f}x"
        + (f" (after {warmup_s:.1f} s compiling the solver)" if warmup_s >= 0.5 else ""),
    ]
    lines += [f"figure: {path}" for path in figures]
    return "\n".join(lines)
