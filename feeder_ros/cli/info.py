"""``feeder info BAG``: what a recorded bag holds (``ros2 bag info`` is not installed here).

Counted from the data (message indexes; ``--verify`` also decompresses and CRC-checks every
chunk), not from metadata.yaml, which a killed recorder leaves stale. Exit status: 0 every
recorded message readable (a last file cut short by a killed recorder included: its messages
are read all the same); 1 some recorded messages are lost (corrupt chunks, missing files, ...);
2 not a bag.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from feeder_ros.cli.main import CommandError

__all__ = ["EPILOG", "HELP", "add_arguments", "run"]

HELP = "show a bag's files, time range, topics and message counts, and any damage found"
EPILOG = (
    "exit status: 0 every recorded message readable; 1 some recorded messages lost (listed); "
    "2 not a bag"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag directory or .mcap file")
    parser.add_argument(
        "--verify",
        action="store_true",
        help="also decompress and CRC-check every chunk (reads the whole bag)",
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
