"""``feeder view [TOPIC ...]``: serve a running feeder's topics live to Foxglove.

Thin: options are parsed here, the view is :func:`feeder_ros.live_view.serve` (rclpy raw
subscriptions handed to a Foxglove WebSocket server of ``foxglove-sdk``). Ctrl-C or SIGTERM stop
it, its normal end (exit status 0); ``--duration`` stops it by itself.
"""

from __future__ import annotations

import argparse

from feeder_ros.cli.arguments import add_topic_selection
from feeder_ros.cli.interrupts import first_interrupt_stops
from feeder_ros.cli.main import CommandError
from feeder_ros.live_view import DEFAULT_PORT, LOCALHOST

__all__ = ["DEFAULT_PORT", "EPILOG", "HELP", "add_arguments", "port_number", "run"]

HELP = "serve a running feeder's topics live to Foxglove (WebSocket, localhost by default)"
EPILOG = """\
Open the view in Foxglove (the desktop app, or app.foxglove.dev in Chrome): Open connection,
Foxglove WebSocket, ws://localhost:8765; then Layouts, Import from file:
config/foxglove_layout.json for speed against target, the drive and diagnostics. Messages are
forwarded as the CDR bytes received, with their ros2msg schemas; nothing is decoded here.

The server has no authentication: --host 0.0.0.0 serves the cell's data to every network the
machine is on. Ctrl-C: the normal end (SIGTERM too, or --duration): exit status 0.

examples:
  # the demo cell's feeder (and /diagnostics) on ws://localhost:8765, until Ctrl-C
  feeder view --namespace /demo_cell/feeder_1
  # two topics on another port, for one minute
  feeder view estimate speed/status --namespace /demo_cell/feeder_1 --port 8766 --duration 60
  # a cell with its live view in one command
  feeder cell --foxglove"""


def port_number(text: str) -> int:
    """A TCP port, 0 (any free port) to 65535."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port (0-65535)")
    return port


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_topic_selection(parser, "serve")
    parser.add_argument(
        "--port",
        type=port_number,
        default=DEFAULT_PORT,
        help=f"WebSocket port (default {DEFAULT_PORT}; 0: any free port)",
    )
    parser.add_argument(
        "--host", default=LOCALHOST, help=f"address to listen on (default {LOCALHOST})"
    )


def run(args: argparse.Namespace) -> int:
    from feeder_ros.live_view import FoxgloveSink, LiveViewError, serve
    from feeder_ros.recording import TopicSelection

    selection = TopicSelection(
        topics=tuple(args.topics),
        namespace=args.namespace,
        duration_s=args.duration,
        use_sim_time=args.use_sim_time,
    )

    def ready(sink: FoxgloveSink) -> None:
        print(f"serving the live view on {sink.url}", flush=True)

    with first_interrupt_stops():  # the cell's SIGINT after the terminal's: one stop
        try:
            summary = serve(selection, args.host, args.port, on_ready=ready)
        except LiveViewError as error:
            raise CommandError(str(error)) from None
        print(summary.text(), flush=True)
    return 0
