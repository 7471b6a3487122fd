"""The live simulator's diagnostics level and message (feeder_ros.physics.simulation_health)."""

from __future__ import annotations

from feeder_ros.physics.simulation_health import ERROR, OK, WARN, simulation_health


def test_on_schedule_is_ok_at_its_achieved_factor() -> None:
    assert simulation_health(None, 0.05, 0.998, 1.0, 0, 2.0) == (OK, "running at 1.00x real time")


def test_behind_schedule_warns_with_the_numbers_an_operator_needs() -> None:
    level, text = simulation_health(None, 0.35, 0.71, 1.0, 4, 2.0)
    assert level == WARN
    assert text == (
        "0.35 s behind the wall clock, running at 0.71x real time (1x requested); "
        "4 drive commands applied late"
    )


def test_behind_by_max_lag_cannot_keep_up() -> None:
    level, text = simulation_health(None, 2.0, 0.4, 1.0, 9, 2.0)
    assert level == ERROR
    assert text.startswith("cannot keep up: 2.00 s behind")


def test_a_failure_outranks_any_lag() -> None:
    assert simulation_health("solver failed at t=3 s", 5.0, 0.1, 1.0, 0, 2.0) == (
        ERROR,
        "solver failed at t=3 s",
    )
