"""``feeder reindex BAG``: repair a bag a killed recorder left (``ros2 bag reindex`` is not
installed here).

metadata.yaml is rewritten from the data, and every file whose one problem is its missing end
(the recorder killed while writing it) is finished: rewritten from its messages with summary
and footer, through a temporary file, so an interrupted repair leaves the original. A file with
other damage (a corrupt chunk, a damaged record, not MCAP at all) is left byte for byte and
named; a listed file that is missing stays listed. The messages lost (the old metadata.yaml's and
the files' own counts against what can be read) are counted and kept in the new metadata.yaml's
``custom_data``, so the repaired bag still reports them. Exit status: 0 the bag is whole now; 1 some
file could not be finished or recorded messages are lost (counted and listed); 2 not a bag
directory.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from feeder_ros.cli.main import CommandError

__all__ = ["EPILOG", "HELP", "add_arguments", "run"]

HELP = "rewrite a bag's metadata.yaml from its data and finish files a killed recorder cut short"
EPILOG = (
    "Messages found lost are counted and kept in metadata.yaml (custom_data): the repaired bag "
    "still reports them. "
    "Exit status: 0 the bag is whole now; 1 some file left as it was (damaged) or recorded "
    "messages lost (counted and listed); 2 not a bag directory"
    """

examples:
  # a bag whose recorder was killed: finish its last file, rewrite metadata.yaml, check it
  feeder reindex run1 && feeder info run1 --verify
  # only metadata.yaml, every .mcap file left as it is
  feeder reindex run1 --metadata-only"""
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag directory")
    parser.add_argument(
        "--metadata-only",
        action="store_true",
        help="only rewrite metadata.yaml; leave every .mcap file as it is",
    )
    parser.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="zstd",
        help="chunk compression of the finished files (default zstd)",
    )


def run(args: argparse.Namespace) -> int:
    from feeder_ros.bag import BagError, MissingBagError, reindex
    from feeder_ros.bag.info_text import describe_info

    try:
        info = reindex(args.bag, finish_files=not args.metadata_only, compression=args.compression)
    except MissingBagError:
        raise  # names the path already (an OSError: exit 2)
    except BagError as error:
        raise CommandError(f"{args.bag}: {error}") from None
    print(describe_info(info))
    left = [p for p in info.problems if p.kind == "not_finished"]
    return 1 if left or info.lost_data() else 0
