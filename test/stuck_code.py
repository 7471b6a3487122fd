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
