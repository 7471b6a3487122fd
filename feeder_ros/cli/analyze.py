"""``feeder analyze BAG [BAG ...]``: segments, speeds, slip, feed rate, diagnostics, sweeps.

The work is in :mod:`feeder_ros.bag.analysis` (streaming, ROS free) and
:mod:`feeder_ros.bag.report` (tables, CSV, JSON, plots, HTML). A bag holding several feeders (a
cell recorded under ``/``) is analysed per feeder, told apart by namespace: one section and one set
of files per feeder (``--namespace NS`` picks one). Exit status: 0 when every bag was analysed
whole; 1 when some bag could not be analysed or lost recorded messages (counted from metadata.yaml
and the MCAP summaries against what can be read: its counts and feed rates are short), the others'
results printed and written all the same; 2 when none could be analysed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from feeder_ros.cli.arguments import non_negative_float
from feeder_ros.cli.outputs import (
    check_apart_from_inputs,
    check_output_dir,
    finish_output_dir,
    output_path,
)
from feeder_ros.cli.progress import ProgressBar

__all__ = ["EPILOG", "HELP", "add_arguments", "run"]

HELP = "analyse recorded feeder bags: drive segments, part speed, slip, feed rate, diagnostics"
EPILOG = (
    "A bag with several feeders (topics /feeder_a/carrier/state, /feeder_b/carrier/state, ...) is "
    "analysed per feeder: one section, and files named <bag>_<namespace>_*, per feeder. "
    "Lost messages are counted (metadata.yaml's and the MCAP summaries' counts against what can "
    "be read) and printed in total and per feeder. Sensor transit speeds count only transits "
    "that passed both sensors within one drive setting (not across a change or its ramp). "
    "Exit status: 0 every bag analysed whole; 1 some bag could not be analysed or lost recorded "
    "messages (a truncated file, corrupt chunks, a missing split file: its counts and feed rates "
    "are short), the other results printed and written all the same; 2 no bag could be analysed"
    """

examples:
  # a bag from 'feeder record': its drive settings, part speeds, slip and feed rate
  feeder analyze run1
  # two bags compared; CSV, JSON, PNG plots and report.html into report/
  feeder analyze run1 run2 --output report
  # one feeder of a bag that holds several; settings shorter than 2 s left out
  feeder analyze run1 --namespace /demo_cell/feeder_1 --min-segment 2"""
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bags", nargs="+", type=Path, metavar="BAG", help="bag directory or .mcap")
    parser.add_argument(
        "--output",
        type=output_path,
        metavar="DIR",
        help="write CSV, JSON, PNG plots and report.html here",
    )
    parser.add_argument(
        "--min-segment",
        type=non_negative_float,
        default=0.5,
        metavar="S",
        help="segments shorter than this (ramps) are left out (default 0.5 s)",
    )
    parser.add_argument(
        "--namespace",
        metavar="NS",
        help="analyse only the feeder under this namespace (e.g. /feeder_a) of bags holding "
        "several; default: every feeder, each on its own",
    )
    parser.add_argument(
        "--progress", action="store_true", help="show a progress bar even if stderr is not a TTY"
    )


class _BagProgress:
    """Per-bag progress: one bar line per bag (the analysis reports ``(bag index, fraction)``)."""

    def __init__(self, names: list[str], enabled: bool) -> None:
        self.names = names
        self.bar = ProgressBar(names[0] if names else "", 1.0, enabled)
        self.bag = 0

    def __call__(self, bag: int, fraction: float) -> None:
        if bag != self.bag:
            self.bag = bag
            self.bar.relabel(self.names[bag])
        self.bar.update(fraction)

    def close(self) -> None:
        self.bar.close()


def run(args: argparse.Namespace) -> int:
    from feeder_ros.bag.analysis import analyze_bags
    from feeder_ros.bag.report import format_summary, write_outputs

    check_apart_from_inputs(args.output, "--output", args.bags)
    check_output_dir(args.output, "--output", holds="report files (CSV, JSON, PNG, HTML)")
    show = bool(args.progress) or sys.stderr.isatty()
    bar = _BagProgress([str(p) for p in args.bags], show)
    try:
        analyses = analyze_bags(
            args.bags, min_segment_s=args.min_segment, namespace=args.namespace, progress=bar
        )
    finally:
        bar.close()
    if not any(a.ok for a in analyses):
        for a in analyses:
            print(f"feeder analyze: error: {a.error}", file=sys.stderr)
        return 2
    print(format_summary(analyses))
    if args.output is not None:
        written = write_outputs(analyses, args.output)
        print(
            f"wrote {len(written)} file(s) to {args.output} (report: {args.output / 'report.html'})"
        )
        finish_output_dir(args.output, written)
    status = 0
    for a in analyses:
        if not a.ok:
            print(f"feeder analyze: error: {a.error}", file=sys.stderr)
            status = 1
        elif a.data_lost:
            print(
                f"feeder analyze: {a.label}: data lost ({a.loss_summary()}): its counts and "
                "feed rates are short",
                file=sys.stderr,
            )
            status = 1
    return status
