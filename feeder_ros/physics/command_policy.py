"""How the live simulator takes a drive command (ROS-free; the platform simulator node's policy).

A command (``drive/command``) says: drive at ``frequency_hz``/``amplitude_n`` (or stop), ramped
over ``ramp_time_s``, from its stamp on. :func:`decide` turns one into what the simulator does,
given the simulation time, how far the simulation lags the wall clock and the command time-out:

* **Malformed** (a ramp that is not finite and >= 0; a driving command whose frequency is not in
  (0, :data:`MAX_COMMAND_FREQUENCY_HZ`] or amplitude not in [0, :data:`MAX_COMMAND_AMPLITUDE_N`]):
  ignored, with the values and their ranges. A stop's frequency and amplitude do not matter.
* **Unstamped** (stamp 0): for now.
* **Stale** (stamped more than ``command_timeout_s`` before the simulation time): a stop now, as
  the time-out would have stopped the drive by then.
* **Ahead only by the lag** (stamped after the simulation time, within the lag plus
  :data:`FUTURE_STAMP_TOLERANCE_S`): the command is for the present, the simulation is behind the
  commander's wall clock: applied now and counted as late.
* **Too far ahead** (beyond the tolerance): ignored, naming the clocks (a commander on the wall
  clock against a simulator on ``/clock``, or a wrong epoch): scheduled there it would also hold
  off the time-out.
* Otherwise scheduled at its stamp. A stop keeps the frequency and drives 0 N. A command that
  repeats the drive in force, for now, only refreshes the time-out's deadline (the schedule
  stays short); the deadline is the command's time plus ``command_timeout_s`` (0: none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

__all__ = [
    "FUTURE_STAMP_TOLERANCE_S",
    "MAX_COMMAND_AMPLITUDE_N",
    "MAX_COMMAND_FREQUENCY_HZ",
    "Command",
    "Decision",
    "decide",
]

#: drive commands beyond these are refused as malformed (no exciter comes near them, and the
#: solver's numbers overflow long before the float range ends)
MAX_COMMAND_FREQUENCY_HZ = 1e5
MAX_COMMAND_AMPLITUDE_N = 1e6
#: a drive command stamped further ahead of the simulation clock is refused (clocks that differ)
FUTURE_STAMP_TOLERANCE_S = 1.0


@dataclass(frozen=True)
class Command:
    """One drive command; ``stamp_s`` on the simulation clock, ``None`` when unstamped."""

    enabled: bool
    frequency_hz: float
    amplitude_n: float
    ramp_time_s: float
    stamp_s: float | None
    stamp_text: str = ""  #: the stamp as the message carried it (for the warnings)


@dataclass(frozen=True)
class Decision:
    """What to do with a command.

    ``action``: ``ignore`` (``warning`` says why); ``stop`` (stale: stop the drive now,
    ``warning`` says why); ``schedule`` (``set_drive(frequency_hz, amplitude_n, at_s, ramp_s)``,
    then the deadline); ``refresh`` (the drive in force repeated: only the deadline)."""

    action: Literal["ignore", "stop", "schedule", "refresh"]
    warning: str = ""
    #: what the warning is about: "malformed", "stale" or "ahead" ("" without a warning); a node
    #: throttles each kind on its own, so that one kind repeated does not hide another
    problem: Literal["", "malformed", "stale", "ahead"] = ""
    at_s: float = math.nan
    frequency_hz: float = math.nan
    amplitude_n: float = math.nan
    ramp_s: float = 0.0
    deadline_s: float = math.inf
    late: bool = False  #: applied now though stamped ahead: the simulation lags


def malformed(command: Command) -> str:
    """Why ``command`` is malformed, or ``""``."""
    ramp_ok = math.isfinite(command.ramp_time_s) and command.ramp_time_s >= 0.0
    drive_ok = not command.enabled or (
        math.isfinite(command.frequency_hz)
        and 0.0 < command.frequency_hz <= MAX_COMMAND_FREQUENCY_HZ
        and 0.0 <= command.amplitude_n <= MAX_COMMAND_AMPLITUDE_N
    )
    if ramp_ok and drive_ok:
        return ""
    return (
        f"ignoring malformed drive command: enabled={command.enabled}, frequency_hz="
        f"{command.frequency_hz!r} (0 < f <= {MAX_COMMAND_FREQUENCY_HZ:g}), amplitude_n="
        f"{command.amplitude_n!r} (0 <= A <= {MAX_COMMAND_AMPLITUDE_N:g}), ramp_time_s="
        f"{command.ramp_time_s!r} (finite, >= 0)"
    )


def decide(
    command: Command,
    now_s: float,
    lag_s: float,
    timeout_s: float,
    drive: tuple[float, float],
) -> Decision:
    """What the simulator at ``now_s`` (lagging the wall clock by ``lag_s`` >= 0, drive in force
    ``drive`` = (frequency, amplitude)) does with ``command``; see the module docstring."""
    problem = malformed(command)
    if problem:
        return Decision("ignore", problem, "malformed")
    at = now_s if command.stamp_s is None else command.stamp_s
    if timeout_s > 0.0 and at < now_s - timeout_s:
        return Decision(
            "stop",
            f"drive command stamped {now_s - at:.3f} s ago (> command_timeout_s={timeout_s}): "
            "treated as stop",
            "stale",
            at_s=now_s,
        )
    late = False
    if now_s < at <= now_s + lag_s + FUTURE_STAMP_TOLERANCE_S:
        at, late = now_s, True
    elif at - now_s > FUTURE_STAMP_TOLERANCE_S:
        return Decision(
            "ignore",
            f"ignoring drive command stamped {at - now_s:.3f} s ahead of the simulation clock "
            f"(stamp {command.stamp_text or f'{at:.9f}'}, more than "
            f"{FUTURE_STAMP_TOLERANCE_S:g} s ahead): do the commander and the simulator use the "
            "same clock (use_sim_time)?",
            "ahead",
        )
    at = max(at, now_s)  # never ahead here: within the lag it is now, beyond it refused
    frequency = command.frequency_hz if command.enabled else drive[0]
    amplitude = command.amplitude_n if command.enabled else 0.0
    deadline = at + timeout_s if timeout_s > 0.0 else math.inf
    action: Literal["schedule", "refresh"] = (
        "schedule" if (frequency, amplitude) != drive else "refresh"
    )
    return Decision(
        action,
        at_s=at,
        frequency_hz=frequency,
        amplitude_n=amplitude,
        ramp_s=command.ramp_time_s,
        deadline_s=deadline,
        late=late,
    )
