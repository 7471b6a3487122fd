"""``feeder info BAG``: what a recorded bag holds (``ros2 bag info`` is not installed here).

Counted from the data (message indexes; ``--verify`` also decompresses and CRC-checks every
chunk, checks every message record against its index and decodes every message), not from
metadata.yaml, which a killed recorder leaves stale. What was recorded is counted from
metadata.yaml and the files' MCAP summaries (statistics) and damaged chunks' message indexes:
the messages lost are given as a number, in total and per topic (a lower bound when a file cut
short leaves the total unknown). Exit status: 0 every recorded message readable (a last file cut
short at a chunk boundary by a killed recorder included: its messages are read all the same, and
the total is reported unknown); 1 some recorded messages are lost (fewer readable than the bag
counts, corrupt chunks, a chunk cut off, missing files, ...); 2 not a bag.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from feeder_ros.cli.main import CommandError

__all__ = ["EPILOG", "HELP", "add_arguments", "run"]

HELP = (
    "show a bag's files, time range, topics and message counts, the messages it lost (counted) "
    "and any damage found"
)
EPILOG = (
    "Lost messages are counted: metadata.yaml's and the MCAP summaries' counts against what can "
    "be read, in total and per topic (a lower bound, said so, when a file cut short leaves the "
    "total unknown). "
    "Exit status: 0 every recorded message readable (also a last file a killed recorder left cut "
    "short at a chunk boundary: total reported unknown); 1 some recorded messages lost (counted "
    "and listed: fewer readable than recorded, corrupt chunks, a chunk cut off by the end of a "
    "file, missing files); 2 not a bag"
    """

examples:
  feeder info run1
  # also decompress, CRC-check and decode everything
  feeder info run1 --verify
  # one file of the bag, as JSON
  feeder info run1/run1_0.mcap --json"""
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag directory or .mcap file")
    parser.add_argument(
        "--verify",
        action="store_true",
        help="also decompress and CRC-check every chunk, check every message record against its "
        "index and decode every message (reads the whole bag); prints what it checked",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")


def run(args: argparse.Namespace) -> int:
    from feeder_ros.bag import BagError, MissingBagError, bag_info
    from feeder_ros.bag.info_text import describe_info, info_as_dict
    from feeder_ros.bag.reader import Bag

    try:
        info = bag_info(Bag(args.bag, warn=False), verify=args.verify)
    except MissingBagError:
        raise  # names the path already (an OSError: exit 2)
    except (BagError, OSError) as error:
        raise CommandError(f"{args.bag}: {error}") from None
    if args.bag.is_file() and any(p.kind == "not_mcap" for p in info.problems):
        raise CommandError(f"{args.bag}: not a bag (the file does not start with the MCAP magic)")
    print(json.dumps(info_as_dict(info), indent=2) if args.json else describe_info(info))
    return 1 if info.lost_data() else 0
