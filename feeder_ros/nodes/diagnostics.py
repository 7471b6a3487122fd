"""One way for every node to build its ``/diagnostics`` entries.

A core says how it is (a level and a message, its values as text); :func:`diagnostic_status`
turns that into a ``diagnostic_msgs/DiagnosticStatus`` and :func:`diagnostic_array` stamps one or
more of them for publishing. Levels are the ints 0 (OK), 1 (WARN), 2 (ERROR), 3 (STALE), as
:class:`feeder_ros.drive.health.Level` and the monitors' levels are, or the message's own bytes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

__all__ = ["diagnostic_array", "diagnostic_status"]


def diagnostic_status(
    name: str, level: int | bytes, message: str, hardware_id: str, values: Mapping[str, str]
) -> DiagnosticStatus:
    """``level``: an int 0-3 or the message's bytes (DiagnosticStatus.OK, ...)."""
    return DiagnosticStatus(
        name=name,
        hardware_id=hardware_id,
        level=level if isinstance(level, bytes) else bytes([int(level)]),
        message=message,
        values=[KeyValue(key=key, value=value) for key, value in values.items()],
    )


def diagnostic_array(stamp: Any, *statuses: DiagnosticStatus) -> DiagnosticArray:
    """The array to publish, stamped ``stamp`` (a builtin_interfaces/Time)."""
    array = DiagnosticArray(status=list(statuses))
    array.header.stamp = stamp
    return array
