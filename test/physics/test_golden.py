"""Golden outputs of the exact physics engine, compared bit for bit (issue 30: "Golden first").

Issue 30 restructures the event-driven engine (``feeder_ros/physics/exact/``: ``advance``,
``_march_group``, the group march, event ordering) and splits ``feeder_ros/physics/simulation.py``
(``simulate``, ``simulate_parts``, ``simulate_carrier``, ``simulate_many``, the live
``FeederSimulator``). The refactor must not change a single bit of any result. These tests rerun
the seeded cases of ``golden_cases.py`` (both stiffness switches, damped and undamped, one- and
two-way coupling, 1 and 1000 parts, drive changes and ramps, live chunks with spawns and parameter
changes, track exits, ``simulate_many`` with and without ``settle_s``, the carrier alone) and
compare every array with the one frozen in ``golden/<case>.npz``: same dtype, same shape, same
values (``np.array_equal(..., equal_nan=True)`` and the same sign of every zero), no tolerance;
arrays too large to store (1000-part sample matrices, long event logs) by the SHA-256 of their
bytes. A failure names the case, the array and the first differing index.

Regenerate the golden files only when the mathematics is meant to change (a model change, a fix
of the solver that changes its results), never to make a refactor pass, and say so in the commit
message::

    .venv/bin/python test/physics/golden_cases.py --write [CASE ...]

(``python test/physics/golden_cases.py`` without ``--write`` compares and prints each case's
time; ``--digest`` prints one hash per case, to compare processes, thread counts or caches.)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
import pytest
from physics.golden_cases import (
    CASES,
    GOLDEN_DIR,
    HASH_ABOVE_BYTES,
    Arrays,
    compare,
    encode,
    golden_path,
    load,
)

from feeder_ros.physics.simulation import EventKind, Phase, limited_threads

#: the cases whose groups or operating points run in parallel (numba prange)
PARALLEL_CASES = (
    "parts_1000_one_way_march",
    "parts_1000_exit_track",
    "many_from_rest",
    "many_after_settling",
)


@pytest.mark.parametrize("case", list(CASES))
def test_the_engine_reproduces_its_golden_output_bit_for_bit(case: str) -> None:
    path = golden_path(case)
    assert path.is_file(), f"{case}: no golden file {path} (golden_cases.py --write {case})"
    problems = compare(case, CASES[case](), load(case))
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("case", PARALLEL_CASES)
def test_the_parallel_cases_do_not_depend_on_the_thread_count(case: str) -> None:
    with limited_threads(1):
        problems = compare(case, CASES[case](), load(case))
    assert not problems, "on one thread:\n" + "\n".join(problems)


def test_every_golden_file_belongs_to_a_case() -> None:
    stored = sorted(path.stem for path in GOLDEN_DIR.glob("*.npz"))
    assert stored == sorted(CASES)


def _any(case: str, suffix: str, test: Callable[[npt.NDArray[np.generic]], npt.ArrayLike]) -> bool:
    """Whether ``test`` holds anywhere in the stored arrays of ``case`` whose names end with
    ``suffix`` (of a hashed array, in its stored subsample)."""
    data = load(case)
    names = [name for name in data if name.endswith((suffix, suffix + "@sample"))]
    return any(bool(np.any(test(data[name]))) for name in names)


def test_the_cases_exercise_what_they_are_named_for() -> None:
    """The frozen outputs hold what each case is there for (read off the golden files)."""
    for case in ("velocity_held_undamped_one_way", "live_march_chunks_one_way", "carrier_only"):
        assert _any(case, "branch", lambda b: b == 0), f"{case}: the carrier is never held"
        assert _any(case, "event_kind", lambda k: k == EventKind.SLIDING_START), case
    for case in ("displacement_undamped_one_way", "displacement_damped_two_way_drive_schedule"):
        assert not _any(case, "branch", lambda b: b == 0), case
    for case in ("parts_1000_exit_track", "few_parts_exit_track"):
        assert _any(case, "part_exit_t_s", np.isfinite), f"{case}: no part leaves the track"
        assert _any(case, "part_phase", lambda p: p == Phase.EXITED), case
    assert _any("live_spawn_and_parameters_two_way", "c5.part_exit_t_s", np.isfinite)
    for case in ("displacement_damped_two_way_drive_schedule", "live_drive_ramps"):
        assert _any(case, "event_kind", lambda k: k == EventKind.DRIVE_CHANGE), case
    for case in ("parts_1000_one_way_march", "parts_1000_two_way", "parts_1000_exit_track"):
        start = load(case)["part_start_x_m"]
        assert start.shape == (1000,)
        assert np.unique(start).size == 1000, f"{case}: the parts are not all distinct"
    settled = load("many_after_settling")
    assert np.isnan(settled["mean_part_speed_mps"]).any()  # gone before the window
    assert np.isfinite(settled["exit_t_s"]).sum() >= 2
    assert np.isfinite(load("many_from_rest")["exit_t_s"]).any()


def _example() -> Arrays:
    rng = np.random.default_rng(0)
    big = rng.normal(size=(300, 40))
    big[5, 3] = np.nan
    return {
        "small": np.array([0.0, 1.5, np.nan, -2.0]),
        "phase": np.array([[0, 1], [2, -1]], np.int8),
        "big": big,
    }


def test_a_changed_bit_is_reported_with_case_array_and_index() -> None:
    """The comparison itself: identical arrays pass (NaN equals NaN, whatever its payload);
    one ulp, a zero's sign, a dtype or a shape fails, naming the case, the array and where."""
    want = encode(_example())
    assert _example()["big"].nbytes > HASH_ABOVE_BYTES
    assert "big@sha256" in want
    assert "big" not in want
    assert "small" in want
    assert compare("demo", _example(), want) == []
    other_nan = _example()
    other_nan["small"][2] = -np.nan
    other_nan["big"][5, 3] = np.float64(np.nan) * -1.0
    assert compare("demo", other_nan, want) == []

    got = _example()
    got["small"][1] = np.nextafter(1.5, 2.0)
    [problem] = compare("demo", got, want)
    assert problem.startswith("demo: small: 1 of 4 elements differ, the first at index (1,)")

    got = _example()
    got["small"][0] = -0.0
    [problem] = compare("demo", got, want)
    assert "small" in problem
    assert "index (0,)" in problem

    got = _example()
    got["big"][200, 7] = np.nextafter(got["big"][200, 7], np.inf)
    [problem] = compare("demo", got, want)
    assert problem.startswith("demo: big: SHA-256 differs")
    # the block of flat elements holding (200, 7), element 8007 of 12000, is named
    assert "the first holds flat elements [7875, 8062) (from index (196, 35))" in problem

    got = _example()
    got["phase"] = got["phase"].astype(np.int64)
    [problem] = compare("demo", got, want)
    assert problem.startswith("demo: phase: dtype/shape int64(2, 2), expected int8(2, 2)")
    got = _example()
    got["big"] = got["big"][:-1]
    [problem] = compare("demo", got, want)
    assert problem.startswith("demo: big: dtype/shape <f8(299, 40), expected <f8(300, 40)")

    got = _example()
    del got["small"]
    got["extra"] = np.zeros(1)
    assert compare("demo", got, want) == [
        "demo: arrays missing from the run: ['small']",
        "demo: arrays not in the golden file: ['extra']",
    ]
