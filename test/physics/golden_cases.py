"""Golden cases of the exact (sharp) physics engine, frozen before issue 30's refactor.

Each case is a short, seeded run through the public API of :mod:`feeder_ros.physics.simulation`
(``simulate``, ``simulate_parts``, ``simulate_carrier``, ``simulate_many``, the live
``FeederSimulator``) and returns its outputs as ``name -> numpy array``: samples, branch, part
arrays, events, per-part totals, the live simulator's state after each chunk, ``ManySummary``
fields. :func:`encode` turns those into what is stored in ``golden/<case>.npz``: small arrays as
they are, large ones (the 1000-part sample matrices, long event logs) as a SHA-256 of their bytes
with their dtype and shape, a SHA-256 per block of their elements and a small fixed subsample.

``test_golden.py`` recomputes every case and compares it with the stored file bit for bit.

Regenerate (only when the mathematics is meant to change, and say so in the commit)::

    .venv/bin/python test/physics/golden_cases.py --write            # every case
    .venv/bin/python test/physics/golden_cases.py --write CASE ...   # some cases

Without ``--write`` the script compares instead (as the test does) and prints each case's time;
``--digest`` prints one SHA-256 per case (to compare processes, thread counts, numba caches).
A hashed array ``name`` is stored as ``name@sha256``, ``name@dtype``, ``name@shape``,
``name@blocks``, ``name@index`` and ``name@sample``.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.drive import DriveChange, DriveSchedule
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import (
    FeederSimulator,
    ManySummary,
    PartSpec,
    SimulationResult,
    simulate,
    simulate_carrier,
    simulate_many,
    simulate_parts,
)

GOLDEN_DIR = Path(__file__).resolve().parent / "golden"

Arrays = dict[str, npt.NDArray[np.generic]]

#: arrays larger than this [bytes] are stored as hashes and a subsample, not as they are
HASH_ABOVE_BYTES = 16 * 1024
#: elements kept of a hashed array (evenly spread over its C-order elements, ends included)
SUBSAMPLE = 64
#: blocks of a hashed array with their own SHA-256 (locates the first difference)
HASH_BLOCKS = 64

#: the fields of a SimulationResult stored for each run or chunk
RESULT_FIELDS = (
    "t_s",
    "carrier_x_m",
    "carrier_v_mps",
    "carrier_a_mps2",
    "branch",
    "part_x_m",
    "part_v_mps",
    "part_phase",
    "event_t_s",
    "event_kind",
    "event_part",
    "part_start_t_s",
    "part_start_x_m",
    "part_end_t_s",
    "part_end_x_m",
    "part_slip_time_s",
    "part_exit_t_s",
)

#: the paper's case study at a drive that makes the parts move (A = 40 N)
CASE_STUDY = FeederParameters(drive_amplitude_n=40.0)


# -- helpers ------------------------------------------------------------------------------------
def result_arrays(run: SimulationResult, prefix: str = "") -> Arrays:
    """Every array of a run (events read in time order), keys prefixed with ``prefix``."""
    return {prefix + name: np.asarray(getattr(run, name)) for name in RESULT_FIELDS}


def simulator_state(sim: FeederSimulator, prefix: str) -> Arrays:
    """The live simulator's state after a chunk: time, carrier x, v and branch, part count."""
    x, v, branch = sim.carrier_state
    return {
        prefix + "state": np.array([sim.time_s, x, v, float(branch), float(sim.part_count)]),
    }


def many_arrays(summary: ManySummary, prefix: str = "") -> Arrays:
    return {
        prefix + "mean_part_speed_mps": np.asarray(summary.mean_part_speed_mps),
        prefix + "slip_fraction": np.asarray(summary.slip_fraction),
        prefix + "exit_t_s": np.asarray(summary.exit_t_s),
    }


def distinct_parts(
    seed: int,
    count: int,
    span_m: float,
    mass_kg: tuple[float, float] = (0.01, 0.2),
    friction: tuple[float, float] = (0.1, 0.4),
) -> list[PartSpec]:
    """``count`` parts, each with its own position in ``[0, span_m)``, mass and friction."""
    rng = np.random.default_rng(seed)
    position = rng.uniform(0.0, span_m, count)
    mass = rng.uniform(*mass_kg, count)
    mu_s = rng.uniform(*friction, count)
    mu_d = mu_s * rng.uniform(0.3, 1.0, count)
    return [
        PartSpec(float(p), float(m), float(s), float(d))
        for p, m, s, d in zip(position, mass, mu_s, mu_d, strict=True)
    ]


def tune(sim: FeederSimulator, **knobs: int) -> None:
    """Set the simulator's path thresholds (``parallel_min_groups``, ``pieces_per_pass``); a
    knob that no longer exists fails loudly instead of silently changing the path taken."""
    for name, value in knobs.items():
        assert isinstance(getattr(sim, name, None), int), f"FeederSimulator has no int {name!r}"
        setattr(sim, name, value)


def grid(duration_s: float, rate_hz: float, start_s: float = 0.0) -> npt.NDArray[np.float64]:
    """Sample times ``start_s + k/rate_hz`` up to ``start_s + duration_s``."""
    n = round(duration_s * rate_hz)
    return np.asarray(start_s + np.arange(n + 1) / rate_hz, dtype=np.float64)


# -- the cases ----------------------------------------------------------------------------------
def displacement_undamped_one_way() -> Arrays:
    """Displacement switching, c = 0, one-way; one default part (the paper's set-up)."""
    return result_arrays(simulate(CASE_STUDY, 0.3, 2000.0, (PartSpec(0.01),)))


def velocity_held_undamped_one_way() -> Arrays:
    """Velocity switching, c = 0, one-way: the carrier is held (branch 0, Filippov sliding)."""
    params = CASE_STUDY.with_changes(stiffness_switch="velocity")
    parts = (PartSpec(), PartSpec(0.02, static_friction=0.3, kinetic_friction=0.12))
    return result_arrays(simulate(params, 0.3, 1000.0, parts))


def velocity_damped_two_way() -> Arrays:
    """Velocity switching, light damping, two-way coupling; three parts of their own mass and
    friction, a V-groove."""
    params = CASE_STUDY.with_changes(
        stiffness_switch="velocity",
        damping_ns_per_m=30.0,
        coupling="two_way",
        drive_frequency_hz=22.0,
        groove_angle_deg=120.0,
    )
    parts = (
        PartSpec(0.0, mass_kg=0.3),
        PartSpec(0.01, mass_kg=0.5, static_friction=0.25, kinetic_friction=0.2),
        PartSpec(0.03, mass_kg=0.2, static_friction=0.12, kinetic_friction=0.05),
    )
    return result_arrays(simulate(params, 0.3, 1000.0, parts))


def displacement_damped_two_way_drive_schedule() -> Arrays:
    """Displacement switching, c = 200 N*s/m, two-way; a drive schedule with a step and ramps."""
    params = CASE_STUDY.with_changes(damping_ns_per_m=200.0, coupling="two_way")
    drive = DriveSchedule(
        29.6,
        40.0,
        (
            DriveChange(0.05, 25.0, 55.0),
            DriveChange(0.1, 35.0, 20.0, ramp_s=0.05),
            DriveChange(0.2, 20.0, 60.0, ramp_s=0.0305),
        ),
    )
    parts = (PartSpec(0.0, mass_kg=0.4), PartSpec(0.02, mass_kg=0.6, static_friction=0.3))
    return result_arrays(simulate(params, 0.3, 1000.0, parts, drive))


def simulate_parts_overdamped() -> Arrays:
    """``simulate_parts`` (coupling forced one-way) with c = 2000 N*s/m: the backward branch is
    over-damped, the forward one under-damped; a strong drive."""
    params = CASE_STUDY.with_changes(
        damping_ns_per_m=2000.0, coupling="two_way", drive_amplitude_n=300.0
    )
    parts = (PartSpec(), PartSpec(0.01, static_friction=0.15, kinetic_friction=0.15))
    return result_arrays(simulate_parts(params, 0.3, 1000.0, parts))


def parts_1000_one_way_march() -> Arrays:
    """1000 parts of distinct position, mass and friction, one-way: the parallel group march."""
    params = CASE_STUDY.with_changes(drive_frequency_hz=25.0, damping_ns_per_m=100.0)
    return result_arrays(simulate(params, 0.2, 1000.0, distinct_parts(1, 1000, 0.2)))


def parts_1000_one_way_global_loop() -> Arrays:
    """The same kind of 1000 parts in the global event loop (the march switched off by its
    threshold ``parallel_min_groups``), with irregular sample times."""
    params = CASE_STUDY.with_changes(drive_frequency_hz=25.0, damping_ns_per_m=100.0)
    sim = FeederSimulator(params, distinct_parts(2, 1000, 0.2))
    tune(sim, parallel_min_groups=10**9)
    samples = np.sort(np.random.default_rng(3).uniform(0.0, 0.05, 40))
    return result_arrays(sim.advance(0.05, samples)) | simulator_state(sim, "")


def parts_1000_two_way() -> Arrays:
    """1000 light parts of distinct position, mass and friction with two-way coupling."""
    params = CASE_STUDY.with_changes(
        coupling="two_way", damping_ns_per_m=50.0, drive_frequency_hz=25.0, drive_amplitude_n=60.0
    )
    parts = distinct_parts(4, 1000, 0.2, mass_kg=(0.0005, 0.003))
    return result_arrays(simulate(params, 0.05, 1000.0, parts))


def parts_1000_exit_track() -> Arrays:
    """1000 distinct parts on a 10 mm track: most leave it (exits inside the group march); the
    march cut into passes of five carrier pieces (``pieces_per_pass``)."""
    params = CASE_STUDY.with_changes(
        drive_frequency_hz=20.0, damping_ns_per_m=100.0, track_length_m=0.01
    )
    sim = FeederSimulator(params, distinct_parts(5, 1000, 0.01))
    tune(sim, pieces_per_pass=5)  # 10 pieces: two passes, each in parallel (1000 * 5 >= 4096)
    return result_arrays(sim.advance(0.5, grid(0.5, 200.0))) | simulator_state(sim, "")


def few_parts_exit_track() -> Arrays:
    """Three parts leave a 4 mm track, in order, in the global event loop."""
    params = CASE_STUDY.with_changes(drive_frequency_hz=20.0, track_length_m=0.004)
    parts = (PartSpec(0.003), PartSpec(0.0), PartSpec(0.0015))
    return result_arrays(simulate(params, 2.0, 500.0, parts))


def live_drive_ramps() -> Arrays:
    """A live simulator under drive commands: ramps (some cut mid-way by the next command), a
    change scheduled ahead (``at_time_s``), repeated commands at one instant, a ramp to zero
    amplitude; advanced in 20 ms ticks with samples on a 1 ms grid (the schedule forgets old
    changes on the way). Starts off rest (``initial_x_m``, ``initial_v_mps``)."""
    params = FeederParameters(damping_ns_per_m=200.0)
    parts = (PartSpec(), PartSpec(0.01, static_friction=0.25, kinetic_friction=0.2))
    sim = FeederSimulator(params, parts, initial_x_m=1e-4, initial_v_mps=-0.01)
    rng = np.random.default_rng(11)
    out: Arrays = {}
    for tick in range(24):
        now = sim.time_s
        if tick == 20:
            sim.set_drive(24.0, 0.0, ramp_s=0.03)  # ramp down to no drive
        else:
            ahead = float(rng.choice([0.0, 0.0, 0.007, 0.031]))
            for _ in range(int(rng.choice([1, 1, 2]))):
                sim.set_drive(
                    float(rng.uniform(20.0, 26.0)),
                    float(rng.uniform(10.0, 60.0)),
                    at_time_s=now + ahead,
                    ramp_s=float(rng.choice([0.02, 0.0, 0.05])),
                )
        prefix = f"c{tick:02d}."
        out |= result_arrays(sim.advance(now + 0.02, now + np.arange(1, 21) * 1e-3), prefix)
        out |= simulator_state(sim, prefix)
    return out


def live_spawn_and_parameters_two_way() -> Arrays:
    """Live, two-way: chunks with and without samples, parts spawned mid-run (one joining a
    sticking group, one of its own friction), ``set_part_friction`` for one part and for all,
    ``set_parameters`` (damping, stiffness, part mass, a shorter track that a part then leaves),
    and ``reset`` followed by a rerun of the first chunk."""
    params = CASE_STUDY.with_changes(coupling="two_way", damping_ns_per_m=20.0)
    sim = FeederSimulator(params, (PartSpec(0.01),))
    out: Arrays = {}

    def chunk(label: str, t_end: float, samples: npt.ArrayLike | None) -> None:
        nonlocal out
        out |= result_arrays(sim.advance(t_end, samples), label + ".")
        out |= simulator_state(sim, label + ".")

    chunk("c0", 0.1, grid(0.1, 1000.0))
    sim.spawn_part(PartSpec(0.02))
    sim.spawn_part(PartSpec(0.0, mass_kg=0.1, static_friction=0.3, kinetic_friction=0.1))
    chunk("c1", 0.13, None)
    chunk("c2", 0.2, grid(0.07, 500.0, 0.13))
    sim.set_part_friction(0.35, 0.3, part=1)
    chunk("c3", 0.25, grid(0.05, 1000.0, 0.2))
    sim.set_parameters(
        sim.params.with_changes(
            damping_ns_per_m=80.0, youngs_modulus_pa=190e9, part_mass_kg=0.08, track_length_m=0.021
        )
    )
    chunk("c4", 0.4, grid(0.15, 1000.0, 0.25))
    sim.set_part_friction(0.15, 0.1)
    chunk("c5", 0.5, grid(0.1, 1000.0, 0.4))
    sim.reset()
    chunk("r0", 0.1, grid(0.1, 1000.0))
    return out


def live_march_chunks_one_way() -> Arrays:
    """Live, one-way, eight distinct frictions: long chunks take the group march, short ones the
    global loop; a part spawned and the parameters changed between them; velocity switching.
    The last chunk starts with a ramp and marches in passes of 16 carrier pieces."""
    params = CASE_STUDY.with_changes(
        stiffness_switch="velocity", damping_ns_per_m=40.0, drive_frequency_hz=26.0
    )
    parts = [
        PartSpec(0.005 * i, static_friction=0.12 + 0.03 * i, kinetic_friction=0.1) for i in range(8)
    ]
    sim = FeederSimulator(params, parts)
    out: Arrays = {}
    out |= result_arrays(sim.advance(0.5, grid(0.5, 400.0)), "c0.") | simulator_state(sim, "c0.")
    sim.spawn_part(PartSpec(0.05, static_friction=0.5, kinetic_friction=0.3))
    for k in range(3):
        now = sim.time_s
        prefix = f"c{k + 1}."
        run = sim.advance(now + 0.02, grid(0.02, 1000.0, now))
        out |= result_arrays(run, prefix) | simulator_state(sim, prefix)
    sim.set_parameters(sim.params.with_changes(damping_ns_per_m=5.0, static_friction=0.22))
    sim.set_drive(30.0, 50.0, ramp_s=0.05)
    tune(sim, pieces_per_pass=16)
    now = sim.time_s
    out |= result_arrays(sim.advance(now + 0.6, grid(0.6, 400.0, now)), "c4.")
    out |= simulator_state(sim, "c4.")
    return out


def many_from_rest() -> Arrays:
    """``simulate_many`` over a few points (switch modes, couplings, damping, a drive schedule)."""
    base = CASE_STUDY.with_changes(damping_ns_per_m=10.0)
    ramp = DriveSchedule(20.0, 30.0, (DriveChange(0.1, 28.0, 50.0, ramp_s=0.05),))
    points: list[FeederParameters | tuple[FeederParameters, DriveSchedule | None]] = [
        base,
        base.with_changes(drive_frequency_hz=22.0, stiffness_switch="velocity"),
        base.with_changes(coupling="two_way", damping_ns_per_m=0.0),
        base.with_changes(drive_frequency_hz=35.0, drive_amplitude_n=80.0, damping_ns_per_m=500.0),
        (base, ramp),
        (base.with_changes(drive_frequency_hz=20.0, track_length_m=0.003), None),
        base.with_changes(drive_frequency_hz=45.0, drive_amplitude_n=15.0),
        base.with_changes(drive_frequency_hz=18.0, stiffness_switch="velocity", coupling="two_way"),
    ]
    part = PartSpec(0.001, static_friction=0.25, kinetic_friction=0.15)
    return many_arrays(simulate_many(points, 0.5, part))


def many_after_settling() -> Arrays:
    """``simulate_many`` with ``settle_s``: parts that leave before, inside and never."""
    base = CASE_STUDY.with_changes(damping_ns_per_m=10.0)
    points: list[FeederParameters | tuple[FeederParameters, DriveSchedule | None]] = [
        base,
        base.with_changes(drive_frequency_hz=10.0, drive_amplitude_n=20.0, track_length_m=1e-3),
        base.with_changes(drive_frequency_hz=20.0, track_length_m=0.004),
        base.with_changes(stiffness_switch="velocity", coupling="two_way"),
    ]
    return many_arrays(simulate_many(points, 0.4, PartSpec(), settle_s=0.3))


def carrier_only() -> Arrays:
    """The carrier alone: two-way (mass M + alpha*m) with velocity switching under a ramped drive,
    and one-way with displacement switching, damped."""
    drive = DriveSchedule(25.0, 10.0, (DriveChange(0.05, 30.0, 60.0, ramp_s=0.1),))
    held = CASE_STUDY.with_changes(stiffness_switch="velocity", coupling="two_way")
    damped = CASE_STUDY.with_changes(damping_ns_per_m=300.0)
    return result_arrays(simulate_carrier(held, 0.3, 1000.0, drive), "velocity.") | result_arrays(
        simulate_carrier(damped, 0.3, 1000.0), "displacement."
    )


def random_points() -> Arrays:
    """Three seeded random operating points around the case study, two parts each."""
    out: Arrays = {}
    for seed in (7, 8, 9):
        rng = np.random.default_rng(seed)
        mu_s = float(rng.uniform(0.1, 0.4))
        params = FeederParameters(
            drive_amplitude_n=float(rng.uniform(5.0, 60.0)),
            drive_frequency_hz=float(rng.uniform(15.0, 60.0)),
            damping_ns_per_m=float(rng.choice([0.0, rng.uniform(1.0, 200.0), 1500.0])),
            static_friction=mu_s,
            kinetic_friction=float(mu_s * rng.uniform(0.3, 1.0)),
            part_mass_kg=float(rng.uniform(0.05, 1.0)),
            stiffness_switch=str(rng.choice(["displacement", "velocity"])),
            coupling=str(rng.choice(["one_way", "two_way"])),
        )
        parts = (PartSpec(), PartSpec(0.01, static_friction=mu_s * 1.5, kinetic_friction=mu_s))
        out |= result_arrays(simulate(params, 0.2, 1000.0, parts), f"seed{seed}.")
    return out


CASES: dict[str, Callable[[], Arrays]] = {
    case.__name__: case
    for case in (
        displacement_undamped_one_way,
        velocity_held_undamped_one_way,
        velocity_damped_two_way,
        displacement_damped_two_way_drive_schedule,
        simulate_parts_overdamped,
        parts_1000_one_way_march,
        parts_1000_one_way_global_loop,
        parts_1000_two_way,
        parts_1000_exit_track,
        few_parts_exit_track,
        live_drive_ramps,
        live_spawn_and_parameters_two_way,
        live_march_chunks_one_way,
        many_from_rest,
        many_after_settling,
        carrier_only,
        random_points,
    )
}


# -- storage ------------------------------------------------------------------------------------
def canonical(array: npt.NDArray[np.generic]) -> npt.NDArray[np.generic]:
    """C-contiguous copy with every NaN as numpy's NaN (NaN payloads and signs are not
    results; signed zeros are kept)."""
    out = np.ascontiguousarray(array)
    if out.dtype.kind in "fc" and np.isnan(out).any():
        out = np.where(np.isnan(out), np.nan, out).astype(out.dtype)
    return out


def sha256(array: npt.NDArray[np.generic]) -> str:
    return hashlib.sha256(canonical(array).tobytes()).hexdigest()


def block_hashes(array: npt.NDArray[np.generic]) -> npt.NDArray[np.str_]:
    """SHA-256 of each of ``HASH_BLOCKS`` consecutive runs of the flat (C-order) elements."""
    flat = canonical(array).ravel()
    edges = block_edges(flat.size)
    return np.array(
        [hashlib.sha256(flat[a:b].tobytes()).hexdigest() for a, b in itertools.pairwise(edges)]
    )


def block_edges(size: int) -> list[int]:
    blocks = min(HASH_BLOCKS, max(size, 1))
    return [size * k // blocks for k in range(blocks + 1)]


def subsample_index(size: int) -> npt.NDArray[np.int64]:
    return np.unique(np.linspace(0, max(size - 1, 0), min(SUBSAMPLE, size)).astype(np.int64))


def encode(arrays: Arrays) -> Arrays:
    """What is stored of a case's arrays: small ones as they are, large ones hashed."""
    stored: Arrays = {}
    for name, array in arrays.items():
        if array.nbytes <= HASH_ABOVE_BYTES:
            stored[name] = canonical(array)
            continue
        index = subsample_index(array.size)
        stored[name + "@sha256"] = np.array(sha256(array))
        stored[name + "@dtype"] = np.array(array.dtype.str)
        stored[name + "@shape"] = np.array(array.shape, dtype=np.int64)
        stored[name + "@blocks"] = block_hashes(array)
        stored[name + "@index"] = index
        stored[name + "@sample"] = canonical(array).ravel()[index]
    return stored


def golden_path(case: str) -> Path:
    return GOLDEN_DIR / f"{case}.npz"


def load(case: str) -> Arrays:
    with np.load(golden_path(case), allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


def write(case: str, arrays: Arrays) -> Path:
    GOLDEN_DIR.mkdir(exist_ok=True)
    path = golden_path(case)
    np.savez_compressed(path, **encode(arrays))  # type: ignore[arg-type]
    return path


# -- comparison ---------------------------------------------------------------------------------
def _same(a: npt.NDArray[np.generic], b: npt.NDArray[np.generic]) -> npt.NDArray[np.bool_]:
    """Element by element: equal values (NaN equal to NaN) with equal signs of zero."""
    if a.dtype.kind in "fc":
        both_nan = np.isnan(a) & np.isnan(b)
        return np.asarray(both_nan | ((a == b) & (np.signbit(a) == np.signbit(b))))
    return np.asarray(a == b)


def _first_difference(a: npt.NDArray[np.generic], b: npt.NDArray[np.generic]) -> str:
    flat = np.flatnonzero(~_same(a, b).ravel())
    if flat.size == 0:
        return "no element differs"
    index = tuple(int(i) for i in np.unravel_index(int(flat[0]), a.shape))
    return (
        f"{flat.size} of {a.size} elements differ, the first at index {index}: "
        f"expected {b.ravel()[flat[0]]!r}, got {a.ravel()[flat[0]]!r}"
    )


def _compare_plain(name: str, got: npt.NDArray[np.generic], want: npt.NDArray[np.generic]) -> str:
    if got.dtype != want.dtype or got.shape != want.shape:
        return f"{name}: dtype/shape {got.dtype}{got.shape}, expected {want.dtype}{want.shape}"
    if np.array_equal(got, want, equal_nan=True) and bool(_same(got, want).all()):
        return ""
    return f"{name}: {_first_difference(got, want)}"


def _compare_hashed(name: str, got: npt.NDArray[np.generic], want: Arrays) -> str:
    dtype, shape = str(want[name + "@dtype"]), tuple(int(n) for n in want[name + "@shape"])
    if got.dtype.str != dtype or got.shape != shape:
        return f"{name}: dtype/shape {got.dtype.str}{got.shape}, expected {dtype}{shape} (hashed)"
    if sha256(got) == str(want[name + "@sha256"]):
        return ""
    message = [f"{name}: SHA-256 differs"]
    blocks = block_hashes(got)
    edges = block_edges(got.size)
    differ = np.flatnonzero(blocks != want[name + "@blocks"])
    if differ.size:
        k = int(differ[0])
        first = tuple(int(i) for i in np.unravel_index(edges[k], shape)) if got.size else ()
        message.append(
            f"{differ.size} of {blocks.size} blocks differ, the first holds flat elements "
            f"[{edges[k]}, {edges[k + 1]}) (from index {first})"
        )
    index = want[name + "@index"]
    sample = canonical(got).ravel()[index]
    wrong = np.flatnonzero(~_same(sample, want[name + "@sample"]))
    if wrong.size:
        j = int(wrong[0])
        at = tuple(int(i) for i in np.unravel_index(int(index[j]), shape))
        message.append(
            f"first differing stored sample at index {at}: expected "
            f"{want[name + '@sample'][j]!r}, got {sample[j]!r}"
        )
    return "; ".join(message)


def compare(case: str, got: Arrays, want: Arrays) -> list[str]:
    """Differences between a case's fresh arrays and its stored golden file (empty: identical)."""
    problems = []
    hashed = {key.rsplit("@", 1)[0] for key in want if "@" in key}
    plain = {key for key in want if "@" not in key}
    missing = sorted((plain | hashed) - set(got))
    extra = sorted(set(got) - plain - hashed)
    if missing:
        problems.append(f"arrays missing from the run: {missing}")
    if extra:
        problems.append(f"arrays not in the golden file: {extra}")
    for name in sorted(set(got) & plain):
        problem = _compare_plain(name, canonical(got[name]), want[name])
        if problem:
            problems.append(problem)
    for name in sorted(set(got) & hashed):
        problem = _compare_hashed(name, got[name], want)
        if problem:
            problems.append(problem)
    return [f"{case}: {problem}" for problem in problems]


def digest(arrays: Arrays) -> str:
    """One SHA-256 over a case's arrays (names, dtypes, shapes, bytes): for quick comparisons
    between processes."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        array = canonical(arrays[name])
        h.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        h.update(array.tobytes())
    return h.hexdigest()


# -- command line -------------------------------------------------------------------------------
def _selected(names: Sequence[str]) -> Iterator[str]:
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        raise SystemExit(f"unknown case(s) {', '.join(unknown)}; known: {', '.join(CASES)}")
    yield from (names or CASES)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("cases", nargs="*", help="case names (default: all)")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="(re)write the golden files")
    mode.add_argument(
        "--digest", action="store_true", help="print one SHA-256 per case (determinism checks)"
    )
    args = parser.parse_args(argv)
    failed = 0
    for case in _selected(args.cases):
        started = time.perf_counter()
        arrays = CASES[case]()
        seconds = time.perf_counter() - started
        if args.write:
            path = write(case, arrays)
            print(f"{case}: {seconds:.3f} s, wrote {path.stat().st_size} bytes")
        elif args.digest:
            print(f"{case} {digest(arrays)}")
        else:
            problems = compare(case, arrays, load(case))
            failed += bool(problems)
            print(f"{case}: {seconds:.3f} s, {'DIFFERS' if problems else 'identical'}")
            for problem in problems:
                print("  " + problem)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
