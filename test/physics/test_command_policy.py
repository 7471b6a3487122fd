"""The live simulator's drive-command policy (pure core): every branch, with the values it
schedules and the reasons it gives."""

from __future__ import annotations

import math

import pytest

from feeder_ros.physics.command_policy import (
    FUTURE_STAMP_TOLERANCE_S,
    MAX_COMMAND_FREQUENCY_HZ,
    Command,
    decide,
)

NOW, LAG, TIMEOUT = 10.0, 0.3, 1.0
DRIVE = (30.0, 40.0)  # in force


def _go(stamp: float | None, frequency: float = 30.0, amplitude: float = 50.0) -> Command:
    return Command(True, frequency, amplitude, 0.2, stamp, "stamp-text")


@pytest.mark.parametrize(
    "command",
    [
        Command(True, math.nan, 10.0, 0.0, None),
        Command(True, 0.0, 10.0, 0.0, None),
        Command(True, MAX_COMMAND_FREQUENCY_HZ * 2, 10.0, 0.0, None),
        Command(True, 30.0, -1.0, 0.0, None),
        Command(True, 30.0, math.inf, 0.0, None),
        Command(False, math.nan, math.nan, -0.1, None),  # a stop's ramp still counts
        Command(False, 30.0, 0.0, math.nan, None),
    ],
)
def test_malformed_commands_are_ignored_naming_the_values(command: Command) -> None:
    decision = decide(command, NOW, LAG, TIMEOUT, DRIVE)
    assert (decision.action, decision.problem) == ("ignore", "malformed")
    assert decision.warning.startswith("ignoring malformed drive command: ")
    assert f"frequency_hz={command.frequency_hz!r}" in decision.warning
    assert f"ramp_time_s={command.ramp_time_s!r} (finite, >= 0)" in decision.warning


def test_a_stop_keeps_the_frequency_whatever_its_fields_say() -> None:
    decision = decide(Command(False, math.nan, math.nan, 0.5, None), NOW, LAG, TIMEOUT, DRIVE)
    assert (decision.action, decision.frequency_hz, decision.amplitude_n) == ("schedule", 30, 0)
    assert (decision.at_s, decision.ramp_s, decision.deadline_s) == (NOW, 0.5, NOW + TIMEOUT)


def test_unstamped_is_now_and_a_repeat_only_refreshes_the_deadline() -> None:
    new = decide(_go(None), NOW, LAG, TIMEOUT, DRIVE)
    assert (new.action, new.at_s, new.amplitude_n, new.late) == ("schedule", NOW, 50.0, False)
    assert (new.warning, new.problem) == ("", "")
    repeat = decide(_go(None, amplitude=40.0), NOW, LAG, TIMEOUT, DRIVE)
    assert (repeat.action, repeat.deadline_s) == ("refresh", NOW + TIMEOUT)
    # stamped ahead within the lag: for the present, and the same drive
    later = decide(_go(NOW + 2.0, amplitude=40.0), NOW, 5.0, TIMEOUT, DRIVE)
    assert (later.action, later.late, later.deadline_s) == ("refresh", True, NOW + TIMEOUT)
    no_timeout = decide(_go(None), NOW, LAG, 0.0, DRIVE)
    assert no_timeout.deadline_s == math.inf


def test_a_stale_command_is_a_stop_and_a_past_one_within_the_timeout_is_now() -> None:
    stale = decide(_go(NOW - TIMEOUT - 0.25), NOW, LAG, TIMEOUT, DRIVE)
    assert (stale.action, stale.problem) == ("stop", "stale")
    assert stale.warning == (
        "drive command stamped 1.250 s ago (> command_timeout_s=1.0): treated as stop"
    )
    past = decide(_go(NOW - 0.5), NOW, LAG, TIMEOUT, DRIVE)
    assert (past.action, past.at_s, past.deadline_s) == ("schedule", NOW, NOW + TIMEOUT)
    # without a time-out nothing is stale
    assert decide(_go(NOW - 100.0), NOW, LAG, 0.0, DRIVE).action == "schedule"


def test_ahead_by_the_lag_is_late_and_beyond_the_tolerance_is_refused() -> None:
    lagging = decide(_go(NOW + LAG + FUTURE_STAMP_TOLERANCE_S), NOW, LAG, TIMEOUT, DRIVE)
    assert (lagging.action, lagging.at_s, lagging.late) == ("schedule", NOW, True)
    far = decide(_go(NOW + LAG + FUTURE_STAMP_TOLERANCE_S + 0.01), NOW, LAG, TIMEOUT, DRIVE)
    assert (far.action, far.problem) == ("ignore", "ahead")
    assert far.warning.startswith(
        "ignoring drive command stamped 1.310 s ahead of the simulation clock (stamp "
        "stamp-text, more than 1 s ahead)"
    )
    assert "use_sim_time" in far.warning
