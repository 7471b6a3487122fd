"""Ctrl-C for the commands it ends normally (``feeder record``, ``feeder view``): the first one
stops the command, further ones while it stops are ignored.

A terminal's Ctrl-C reaches the whole process group: a ``feeder view`` started by ``feeder cell``
gets it, and then once more from the cell, which stops its children with SIGINT. A second
``KeyboardInterrupt`` raised while the first one's stop was closing the bag or the server, or
printing the summary, cut that short ("feeder: interrupted", exit 130, no summary). A teardown
that hangs is still ended, by the runner's watchdog (``runner.TEARDOWN_LIMIT_S``).

While rclpy's SIGINT handler is installed the first Ctrl-C raises nothing: rclpy's signal thread
shuts the context down and the spin loop, which watches it, stops by itself. An exception raised
from a signal handler lands in whatever Python runs at that moment; in a finalizer (CI saw
rclpy's ``Task.__del__``) Python swallows it and prints its traceback.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["first_interrupt_stops"]


def rclpy_handles_sigint() -> bool:
    """Whether rclpy's SIGINT handler is installed (it shuts the contexts down on a Ctrl-C).
    Imports nothing: without rclpy loaded, no."""
    signals = sys.modules.get("rclpy.signals")
    return signals is not None and signals.get_current_signal_handlers_options().name in (
        "SIGINT",
        "ALL",
    )


@contextmanager
def first_interrupt_stops() -> Iterator[None]:
    """Within the block, the first SIGINT stops: it raises ``KeyboardInterrupt`` unless rclpy's
    handler (installed over this one while a context runs; it calls this one too) shuts the
    context down instead. Later ones do nothing, also after the block. Not interrupted, the
    block restores the previous handler. Outside the main thread (where no handler can be set)
    a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    interrupted = False

    def on_sigint(signum: int, frame: FrameType | None) -> None:
        nonlocal interrupted
        if not interrupted:
            interrupted = True
            if not rclpy_handles_sigint():
                raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    finally:
        # once interrupted the process is ending: SIGINT stays ignored to its exit (Python's
        # finalisation would otherwise restore the default action, and a late one kill it)
        signal.signal(signal.SIGINT, signal.SIG_IGN if interrupted else previous)
