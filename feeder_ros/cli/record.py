"""``feeder record [TOPIC ...]``: record a feeder's topics from the ROS graph into a bag.

Thin: options are parsed here, the recording is :func:`feeder_ros.recording.record` (rclpy, raw
subscriptions) writing through :class:`feeder_ros.bag.BagWriter` (rosbag2 bag, MCAP storage,
chunked zstd by default). Ctrl-C or SIGTERM stop it cleanly, its normal end (exit status 0, the bag
closed); ``--duration`` stops it by itself.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from feeder_ros.cli.arguments import add_topic_selection
from feeder_ros.cli.interrupts import first_interrupt_stops
from feeder_ros.cli.main import CommandError
from feeder_ros.cli.outputs import check_output_dir, output_path

__all__ = ["EPILOG", "HELP", "add_arguments", "run"]

HELP = "record feeder topics from the ROS graph into a rosbag2 (MCAP) bag"
EPILOG = """\
Ctrl-C: the normal way to end a recording (SIGTERM too, or --duration): the bag is closed,
complete and readable, its summary printed, then exit status 0 (1 if the middleware's teardown
hung, ended after 5 s; the bag is closed before it). A Ctrl-C before the bag exists (while the
command starts) records nothing: exit status 130.

examples:
  # every topic of the demo cell's feeder (and /diagnostics) into run1, until Ctrl-C
  feeder record --namespace /demo_cell/feeder_1 -o run1
  # two topics (relative names are taken in --namespace), lz4 chunks
  feeder record parts/state estimate --namespace /demo_cell/feeder_1 --compression lz4 -o run2
  # one minute of everything, a new file every 512 MiB
  feeder record --duration 60 --max-bag-size 512M -o run3"""
_UNITS = {"": 1, "k": 1 << 10, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
_SIZE_MAX = 1 << 40  # bytes: a chunk or bag file this large is a typo


def _size(text: str) -> int:
    """Bytes, with an optional K/M/G suffix (binary)."""
    body, unit = (text[:-1], text[-1]) if text and text[-1] in "kKMG" else (text, "")
    try:
        value = float(body)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a size (e.g. 4096, 64K, 512M)") from None
    if not (value >= 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0")
    size = value * _UNITS[unit]
    if size > _SIZE_MAX:
        raise argparse.ArgumentTypeError(f"{text!r} is too large (at most 1024G)")
    if 0 < size < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is less than one byte")
    return int(size)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (value >= 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0 and finite")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_topic_selection(parser, "record")
    parser.add_argument(
        "-o",
        "--output",
        type=output_path,
        help="bag directory to create (default: feeder_<date-time>)",
    )
    parser.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="zstd",
        help="chunk compression (default zstd)",
    )
    parser.add_argument(
        "--chunk-size",
        type=_size,
        default=1 << 20,
        metavar="BYTES",
        help="uncompressed bytes per chunk (default 1M)",
    )
    parser.add_argument(
        "--max-bag-size",
        type=_size,
        default=0,
        metavar="BYTES",
        help="start a new file after this many bytes (0: never)",
    )
    parser.add_argument(
        "--max-bag-duration",
        type=_seconds,
        default=0.0,
        metavar="S",
        help="start a new file after this many seconds (0: never)",
    )


def run(args: argparse.Namespace) -> int:
    if args.chunk_size <= 0:
        raise CommandError(f"--chunk-size={args.chunk_size} must be > 0 bytes")
    output = args.output or Path(time.strftime("feeder_%Y%m%d-%H%M%S"))
    # before rclpy is loaded: refused at once (BagWriter refuses a directory in use)
    check_output_dir(output, "--output", holds="bag files (metadata.yaml, .mcap)")

    from feeder_ros.bag.errors import BagError
    from feeder_ros.recording import RecordingOptions, record

    options = RecordingOptions(
        output=output,
        topics=tuple(args.topics),
        namespace=args.namespace,
        compression=args.compression,
        chunk_size=args.chunk_size,
        max_file_size=args.max_bag_size,
        max_file_duration_s=args.max_bag_duration,
        duration_s=args.duration,
        use_sim_time=args.use_sim_time,
    )
    with first_interrupt_stops():  # the cell's SIGINT after the terminal's: one stop
        try:
            summary = record(
                options, on_ready=lambda: print(f"recording into {output}", flush=True)
            )
        except BagError as error:
            raise CommandError(str(error)) from None
        print(summary.text(), flush=True)
    return 0
