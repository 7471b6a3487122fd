"""The live simulator's health for ``/diagnostics`` (ROS-free): one level and one message.

A simulation that failed is an ERROR naming the failure. A simulation paced to the wall clock
that falls behind its schedule by 0.1 s or more is a WARN saying by how much, at what achieved
against requested real-time factor and how many drive commands it applied late; behind by
``max_lag_s`` or more it cannot keep up (ERROR). Otherwise it is OK at its achieved factor.
Levels are diagnostic_msgs' OK (0), WARN (1) and ERROR (2).
"""

from __future__ import annotations

__all__ = ["ERROR", "LAG_WARN_S", "OK", "WARN", "simulation_health"]

OK, WARN, ERROR = 0, 1, 2
LAG_WARN_S = 0.1  #: behind its schedule by this much, a paced simulation is a WARN


def simulation_health(
    failure: str | None,
    lag_s: float,
    achieved_factor: float,
    requested_factor: float,
    late_commands: int,
    max_lag_s: float,
) -> tuple[int, str]:
    """``(level, message)``; ``lag_s`` is 0 for an unpaced run (requested factor 0)."""
    if failure is not None:
        return ERROR, failure
    if lag_s < LAG_WARN_S:
        return OK, f"running at {achieved_factor:.2f}x real time"
    behind = (
        f"{lag_s:.2f} s behind the wall clock, running at {achieved_factor:.2f}x real time "
        f"({requested_factor:g}x requested); {late_commands} drive commands applied late"
    )
    if lag_s >= max_lag_s:
        return ERROR, "cannot keep up: " + behind
    return WARN, behind
