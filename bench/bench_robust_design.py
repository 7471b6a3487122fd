#!/usr/bin/env python3
"""The robust design search against evaluating every sample design one by one (issue 32).

Issue 32's target: "The robust search uses the physics core's batch runner and the model's
homogeneity in A as the nominal search does; measure it against evaluating every sample design
one by one (same run) and against the nominal search, in ``bench/``, and keep a robust search of
the default space under a minute on this machine type."

On the default space (``config/design.yaml``, the ``realistic`` plant), in one run:

1. the nominal search (:func:`~feeder_ros.design.optimizer.optimize`, seed 0);
2. the robust search (:func:`~feeder_ros.design.robust_search.robust_search`: per geometry one
   batch of margins runs, homogeneity in A for every amplitude, one batch of speed runs at the
   robust amplitude), over the nominal search's best geometries alone, and then with 10
   generations of evolution as ``feeder design`` runs it;
3. the naive way to the same answer for one candidate geometry: the drawn plants at each of
   ``--amplitudes`` amplitudes between the bounds, every (amplitude, plant) simulated on its own
   (``evaluate_designs([plant])``: margins and speed), timed and scaled to every geometry the
   robust search measured. Scaled, not run in full: it would take minutes. Its answer for
   that candidate is checked against the robust search's: the amplitude grid cannot beat
   homogeneity's exact interval ends, so the naive amplitude is at most the robust one.

Run: ``python bench/bench_robust_design.py [--quick] [--output FILE.md]``; exit 1 when a verdict
fails.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from feeder_ros.cli.sim import load_parameters  # noqa: E402
from feeder_ros.design.optimizer import DesignProblem, evaluate_designs, optimize  # noqa: E402
from feeder_ros.design.robust_search import chance_lower_bound, robust_search  # noqa: E402
from feeder_ros.design.robustness import drawn_plants  # noqa: E402
from feeder_ros.design.space import load_design_config  # noqa: E402
from feeder_ros.design.stick_slip_conditions import condition_values  # noqa: E402

GENERATIONS = 10  # as `feeder design` by default


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="8 amplitudes for the naive way")
    parser.add_argument("--amplitudes", type=int, default=24, help="naive amplitude grid")
    parser.add_argument("--output", type=Path, help="also write the markdown here")
    args = parser.parse_args(argv)
    grid = 8 if args.quick else args.amplitudes
    plant = load_parameters(REPO / "config" / "platform_simulator.yaml", preset="realistic")
    config = load_design_config(REPO / "config" / "design.yaml")
    problem = DesignProblem(config.space, plant, config.limits, config.window)
    tolerances = config.tolerances
    evaluate_designs([plant], problem.window)  # compile the kernels outside the timings

    started = time.perf_counter()
    nominal = optimize(problem, seed=0)
    nominal_s = time.perf_counter() - started
    started = time.perf_counter()
    derated = robust_search(problem, nominal.ranked, tolerances)
    derated_s = time.perf_counter() - started
    started = time.perf_counter()
    robust = robust_search(problem, nominal.ranked, tolerances, generations=GENERATIONS)
    robust_s = time.perf_counter() - started
    assert robust.best is not None, robust.message
    assert derated.best is not None, derated.message
    geometries = robust.geometries

    # the naive way, for the robust optimum's geometry
    variable = problem.space.variables[problem.space.names.index("drive_amplitude_n")]
    amplitudes = np.linspace(variable.lower, variable.upper, grid)
    started = time.perf_counter()
    met_counts = []
    for amplitude in amplitudes:
        params = robust.best.params.with_changes(drive_amplitude_n=float(amplitude))
        met = 0
        for drawn in drawn_plants(params, tolerances):
            evaluation = evaluate_designs([drawn], problem.window, problem.part)[0]
            met += bool(np.all(condition_values(evaluation.margins, problem.limits) >= 0.0))
        met_counts.append(met)
    naive_one_s = time.perf_counter() - started
    naive_s = naive_one_s * geometries
    feasible = [
        a
        for a, m in zip(amplitudes, met_counts, strict=True)
        if chance_lower_bound(m, tolerances.samples) >= tolerances.probability
    ]
    naive_amplitude = max(feasible) if feasible else float("nan")
    robust_amplitude = robust.best.params.drive_amplitude_n
    consistent = not feasible or naive_amplitude <= robust_amplitude * (1 + 1e-9)

    total_s = nominal_s + robust_s
    lines = [
        f"Default space, {tolerances.samples} drawn plants per design, p = "
        f"{tolerances.probability:g}.",
        "",
        "| | wall time | runs |",
        "|---|---:|---:|",
        f"| nominal search | {nominal_s:.2f} s | {nominal.evaluations} designs |",
        f"| robust: the nominal search's {derated.geometries} best geometries derated | "
        f"{derated_s:.2f} s | {derated.runs} |",
        f"| robust search: those, then {GENERATIONS} generations of evolution "
        f"({geometries} geometries) | {robust_s:.2f} s | {robust.runs} |",
        f"| naive, one geometry, {grid} amplitudes one by one | {naive_one_s:.2f} s | "
        f"{grid * tolerances.samples} |",
        f"| naive, scaled to {geometries} geometries | {naive_s:.0f} s | "
        f"{geometries * grid * tolerances.samples} |",
        "",
        f"- robust search against naive: {naive_s / robust_s:.0f}x faster; against the nominal "
        f"search: {robust_s / nominal_s:.2f}x its time",
        f"- nominal + robust search: {total_s:.1f} s (target < 60 s): "
        f"{'met' if total_s < 60.0 else 'MISSED'}",
        f"- robust optimum: A = {robust_amplitude:.4g} N, speed >= "
        f"{1e3 * robust.best.speed_quantile_mps:.3g} mm/s in {100 * tolerances.probability:g} % "
        f"of the drawn plants (derated candidates only: "
        f"{1e3 * derated.best.speed_quantile_mps:.3g} mm/s); the naive grid's largest robust "
        f"amplitude "
        f"{naive_amplitude:.4g} N (at most the exact one: "
        f"{'yes' if consistent else 'NO'})",
    ]
    text = "\n".join(lines) + "\n"
    sys.stdout.write(text)
    if args.output is not None:
        args.output.write_text(text, encoding="utf-8")
    return 0 if total_s < 60.0 and consistent else 1


if __name__ == "__main__":
    sys.exit(main())
