"""Source for test scripts that must get stuck in compiled code (no ROS imports)."""

from __future__ import annotations

#: The start of a test script that gets stuck: ``spin(np.zeros(4))`` never returns and holds the
#: GIL, like a C call stuck in the DDS teardown (``spin`` is compiled here, before the stop).
STUCK_SPIN_SOURCE = """
import numpy as np
from numba import njit


@njit
def spin(a):
    k = 0
    while a[0] >= 0.0:  # never ends: a[0] only grows
        a[k % 4] += 1.0
        k += 1
    return k


spin(np.array([-1.0, 0.0, 0.0, 0.0]))
"""

#: What a script of :func:`stuck_teardown_script` prints on stderr when its watchdog fires.
TEARDOWN_TIMEOUT_TEXT = "Timeout (0:00:03)!"


def stuck_teardown_script(patch_and_run: str) -> str:
    """A script running a feeder entry point whose middleware teardown gets stuck for good.

    The script defines ``stuck(self)`` (spins, holding the GIL) and sets the teardown limit to
    3 s; ``patch_and_run`` puts ``stuck`` in place of a ``destroy_node`` and runs the entry point
    (``sys`` is imported).
    """
    prelude = """
import sys

from feeder_ros.nodes import runner

runner.TEARDOWN_LIMIT_S = 3.0


def stuck(self):
    spin(np.zeros(4))


"""
    return STUCK_SPIN_SOURCE + prelude + patch_and_run
