"""Global search of the carrier design: fastest parts, or a target speed with the least force.

Formulation (the paper's "future work: parametric optimization ... under desired stick-slip
conditions"):

* variables: a :class:`~feeder_ros.design.space.DesignSpace` (``L_f``, ``L_b``, ``h``, ``q``,
  ``theta``, ``f_d``, ``A`` within bounds; ``q`` integer); every other parameter is the plant's;
* objective ``max-speed``: maximise the part's mean forward speed; ``min-force``: minimise the drive
  amplitude ``A`` subject to ``speed >= target_speed_mps`` (as the fraction ``speed/target - 1``);
* constraints: set S and the validity limits of
  :mod:`~feeder_ros.design.stick_slip_conditions`, each as a fraction that is >= 0 when met, handed
  to :func:`scipy.optimize.differential_evolution` as a ``NonlinearConstraint`` (feasibility rules:
  a design that meets every constraint beats one that does not, among those the lower objective
  wins, among the others the smaller summed violation);
* evaluation: one part put on the carrier at rest at t = 0; its mean speed over the window
  ``[settle_s, settle_s + window_s]`` (exact, :func:`~feeder_ros.physics.simulation.simulate_many`,
  the whole population in one parallel call) and the carrier's peaks over the same window. The
  track is made long enough for the part to stay on it (the plant's ``track_length_m`` is kept in
  the reported design). The window is only steady if the plant is damped (``c > 0``, transient
  ``exp(-c*t/(2*M_eq))``); undamped, the case study is chaotic and the speed is a window statistic.

The search is reproducible: a seeded generator drives the optimiser and the solver is
deterministic. Each population is evaluated once (the constraint call evaluates and caches; the
objective call reads the cache).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Literal, cast

import numpy as np
import numpy.typing as npt
from scipy.optimize import Bounds, NonlinearConstraint, OptimizeResult, differential_evolution

from feeder_ros.design.objectives import OBJECTIVES
from feeder_ros.design.space import DesignError, DesignSpace
from feeder_ros.design.stick_slip_conditions import (
    CONDITION_NAMES,
    ConditionLimits,
    EvaluationWindow,
    StickSlipMargins,
    condition_values,
    stick_slip_margins_many,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import PartSpec, simulate_many

__all__ = [
    "EVALUATION_TRACK_M",
    "OBJECTIVES",
    "DesignEvaluation",
    "DesignProblem",
    "DesignResult",
    "Objective",
    "evaluate_designs",
    "optimize",
    "population_size",
]

F64 = npt.NDArray[np.float64]
Objective = Literal["max-speed", "min-force"]
#: track length during an evaluation: long enough that no part leaves it
EVALUATION_TRACK_M: Final = 1.0e6
#: feasible designs a result keeps, best first
RANKED: Final = 64
#: called after each evaluated batch with (designs evaluated so far, designs planned)
ProgressCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class DesignEvaluation:
    """One design as the search saw it: steady-state part speed, slip fraction, set-S margins."""

    params: FeederParameters
    speed_mps: float  # the part's mean speed over the window (nan: not measurable)
    slip_fraction: float
    margins: StickSlipMargins


def evaluate_designs(
    points: Sequence[FeederParameters],
    window: EvaluationWindow | None = None,
    part: PartSpec | None = None,
) -> list[DesignEvaluation]:
    """Evaluate designs: all part speeds in one parallel ``simulate_many`` call, then the margins.

    The returned ``params`` are the given ones (their own track length); the runs use
    :data:`EVALUATION_TRACK_M`.
    """
    if not points:
        return []
    window = window if window is not None else EvaluationWindow()
    part = part if part is not None else PartSpec()
    runs = [p.with_changes(track_length_m=EVALUATION_TRACK_M) for p in points]
    summary = simulate_many(runs, window.window_s, part=part, settle_s=window.settle_s)
    margins = stick_slip_margins_many(runs, window)
    return [
        DesignEvaluation(
            params=params,
            speed_mps=float(summary.mean_part_speed_mps[k]),
            slip_fraction=float(summary.slip_fraction[k]),
            margins=margins[k],
        )
        for k, params in enumerate(points)
    ]


@dataclass(frozen=True)
class DesignProblem:
    """What to search: space, plant, limits, window, objective (and its target speed), part."""

    space: DesignSpace
    plant: FeederParameters
    limits: ConditionLimits = field(default_factory=ConditionLimits)
    window: EvaluationWindow = field(default_factory=EvaluationWindow)
    objective: Objective = "max-speed"
    target_speed_mps: float | None = None
    part: PartSpec = field(default_factory=PartSpec)

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise DesignError(f"objective={self.objective!r} is not one of {', '.join(OBJECTIVES)}")
        if self.objective == "min-force":
            target = self.target_speed_mps
            if target is None or not (math.isfinite(target) and target > 0.0):
                raise DesignError(
                    f"objective min-force needs a target speed > 0 (got {target!r} m/s)"
                )
            if "drive_amplitude_n" not in self.space.names:
                raise DesignError(
                    "objective min-force searches the drive amplitude: "
                    "variables.drive_amplitude_n is missing"
                )
        if self.plant.stiffness_model != "sharp":
            raise DesignError(
                f"stiffness_model={self.plant.stiffness_model!r}: the design search uses the "
                "exact sharp model"
            )

    @property
    def constraint_names(self) -> tuple[str, ...]:
        extra = ("target_speed",) if self.objective == "min-force" else ()
        return CONDITION_NAMES + extra

    def constraints(self, evaluation: DesignEvaluation) -> F64:
        """Every constraint as a fraction, >= 0 when met (order: :attr:`constraint_names`)."""
        values = condition_values(evaluation.margins, self.limits)
        if self.objective == "min-force":
            assert self.target_speed_mps is not None
            speed = evaluation.speed_mps if math.isfinite(evaluation.speed_mps) else -math.inf
            values = np.append(values, max(speed / self.target_speed_mps - 1.0, -1e3))
        return values

    def feasible(self, evaluation: DesignEvaluation) -> bool:
        return bool(np.all(self.constraints(evaluation) >= 0.0))

    def objective_value(self, evaluation: DesignEvaluation) -> float:
        """Minimised: ``-speed`` (max-speed) or the drive amplitude in N (min-force)."""
        if self.objective == "min-force":
            return float(evaluation.params.drive_amplitude_n)
        speed = evaluation.speed_mps
        return -speed if math.isfinite(speed) else math.inf

    def evaluate(self, vectors: Sequence[npt.ArrayLike]) -> list[DesignEvaluation]:
        points = [self.space.to_parameters(x, self.plant) for x in vectors]
        return evaluate_designs(points, self.window, self.part)


def population_size(space: DesignSpace, population: int) -> tuple[int, int]:
    """(scipy ``popsize`` multiplier, members) for about ``population`` members (at least 5)."""
    multiplier = max(1, math.ceil(max(population, 5) / space.size))
    return multiplier, multiplier * space.size


@dataclass(frozen=True)
class DesignResult:
    """The optimum and how it was found."""

    problem: DesignProblem
    best: DesignEvaluation
    feasible: bool  # meets set S, the validity limits (and the target speed)
    objective_value: float
    constraint_values: F64  # order: problem.constraint_names
    evaluations: int  # designs simulated
    generations: int
    wall_time_s: float
    message: str
    #: convergence: (designs evaluated, best feasible objective so far; nan before the first)
    history: tuple[tuple[int, float], ...] = field(default=())
    #: the feasible designs evaluated, best first (at most :data:`RANKED`): robust candidates
    ranked: tuple[DesignEvaluation, ...] = field(default=())

    @property
    def params(self) -> FeederParameters:
        return self.best.params

    @property
    def speed_mps(self) -> float:
        return self.best.speed_mps

    @property
    def margins(self) -> StickSlipMargins:
        return self.best.margins


class _Evaluator:
    """Evaluates each population once; remembers the best design under the feasibility rules."""

    def __init__(self, problem: DesignProblem, planned: int, progress: ProgressCallback | None):
        self.problem = problem
        self.planned = planned
        self.progress = progress
        self.evaluations = 0
        self.history: list[tuple[int, float]] = []
        self._cache: dict[bytes, tuple[DesignEvaluation, F64, float]] = {}
        self.best: tuple[DesignEvaluation, F64, float] | None = None

    @staticmethod
    def _key(x: F64) -> bytes:
        return np.ascontiguousarray(x, dtype=np.float64).tobytes()

    def _better(self, a: tuple[DesignEvaluation, F64, float]) -> bool:
        if self.best is None:
            return True
        _, cons_a, obj_a = a
        _, cons_b, obj_b = self.best
        feas_a, feas_b = bool(np.all(cons_a >= 0)), bool(np.all(cons_b >= 0))
        if feas_a != feas_b:
            return feas_a
        if feas_a:
            return obj_a < obj_b
        return float(np.sum(np.minimum(cons_a, 0.0))) > float(np.sum(np.minimum(cons_b, 0.0)))

    def ensure(self, columns: F64) -> list[tuple[DesignEvaluation, F64, float]]:
        """Entries for the designs in the columns of ``columns`` (shape (N, S) or (N,))."""
        vectors = np.atleast_2d(columns.T) if columns.ndim == 2 else columns[np.newaxis, :]
        missing = [x for x in vectors if self._key(x) not in self._cache]
        if missing:
            for x, evaluation in zip(missing, self.problem.evaluate(missing), strict=True):
                entry = (
                    evaluation,
                    self.problem.constraints(evaluation),
                    self.problem.objective_value(evaluation),
                )
                self._cache[self._key(x)] = entry
                if self._better(entry):
                    self.best = entry
            self.evaluations += len(missing)
            best = self.best
            if best is not None and bool(np.all(best[1] >= 0)):
                self.history.append((self.evaluations, best[2]))
            else:
                self.history.append((self.evaluations, math.nan))
            if self.progress is not None:
                self.progress(self.evaluations, self.planned)
        return [self._cache[self._key(x)] for x in vectors]

    def ranked(self, count: int) -> tuple[DesignEvaluation, ...]:
        """The ``count`` best feasible designs evaluated, best first."""
        feasible = [entry for entry in self._cache.values() if bool(np.all(entry[1] >= 0))]
        feasible.sort(key=lambda entry: entry[2])
        return tuple(entry[0] for entry in feasible[:count])

    def constraint_fn(self, columns: F64) -> F64:
        entries = self.ensure(np.asarray(columns, dtype=np.float64))
        out = np.array([entry[1] for entry in entries], dtype=np.float64)  # (S, M)
        return out.T if np.asarray(columns).ndim == 2 else out[0]

    def objective_fn(self, columns: F64) -> F64:
        entries = self.ensure(np.asarray(columns, dtype=np.float64))
        out = np.array([entry[2] for entry in entries], dtype=np.float64)
        return out if np.asarray(columns).ndim == 2 else out[:1]


def optimize(
    problem: DesignProblem,
    *,
    seed: int = 0,
    generations: int = 30,
    population: int = 42,
    max_evaluations: int | None = None,
    amplitude_line_points: int = 12,
    progress: ProgressCallback | None = None,
) -> DesignResult:
    """Differential evolution over ``problem.space`` (seeded, whole populations in parallel).

    ``population`` members (rounded up to a multiple of the number of variables); at most
    ``generations`` generations after the initial population, fewer if ``max_evaluations``
    (designs simulated, the initial population included) allows fewer, or if the population
    converges (scipy's ``tol``). No gradient polish: the speed is not smooth in the design
    (stick-slip regimes change), and the best design found is reported as evaluated.

    Instead, an exact-physics line search in the drive amplitude (``amplitude_line_points``
    designs per batch, 0 to skip): the carrier alone is positively homogeneous in ``A``
    (MODEL-NOTES), so its peaks and stroke scale with ``A``, and the amplitudes at which the best
    design meets set S and the stroke limit, ``[(1 + r)*a_s/a_bwd, (1 - r)*a_s/a_fwd]*A`` (``r``
    the required margin; within the bounds), follow from its own evaluation. That interval is
    evaluated in one batch (its upper end is where ``max-speed`` optima lie: the speed rises up to
    the set-S boundary); for ``min-force`` a second batch refines between the smallest amplitude
    that reaches the target and the one below. The best of all evaluated designs is the result.
    """
    if generations < 1:
        raise DesignError(f"generations={generations!r} must be >= 1")
    multiplier, members = population_size(problem.space, population)
    if max_evaluations is not None:
        if max_evaluations < 2 * members:
            raise DesignError(
                f"max_evaluations={max_evaluations!r} is less than two populations "
                f"(2 x {members} designs)"
            )
        generations = min(generations, max_evaluations // members - 1)
    planned = members * (generations + 1)
    evaluator = _Evaluator(problem, planned, progress)
    constraint = NonlinearConstraint(evaluator.constraint_fn, 0.0, np.inf, keep_feasible=False)
    started = time.perf_counter()
    generation_count = 0

    def count(intermediate_result: OptimizeResult) -> None:
        nonlocal generation_count
        generation_count += 1

    result = differential_evolution(
        cast(Any, evaluator.objective_fn),  # vectorized: (N, S) -> (S,), not the scalar form
        Bounds(problem.space.lower, problem.space.upper),
        maxiter=generations,
        popsize=multiplier,
        rng=np.random.default_rng(seed),
        callback=count,
        polish=False,
        init="latinhypercube",
        updating="deferred",
        vectorized=True,
        constraints=constraint,
        integrality=problem.space.integrality,
    )
    message = f"differential evolution: {result.message}"
    assert evaluator.best is not None
    if amplitude_line_points > 0 and "drive_amplitude_n" in problem.space.names:
        before = evaluator.best[0].params.drive_amplitude_n
        count_before = evaluator.evaluations
        _amplitude_search(problem, evaluator, amplitude_line_points)
        after = evaluator.best[0].params.drive_amplitude_n
        message += (
            f"; amplitude line search: {evaluator.evaluations - count_before} designs, "
            f"A {before:.4g} -> {after:.4g} N"
        )
    wall = time.perf_counter() - started
    best, constraints, objective = evaluator.best
    return DesignResult(
        problem=problem,
        best=best,
        feasible=bool(np.all(constraints >= 0.0)),
        objective_value=objective,
        constraint_values=constraints,
        evaluations=evaluator.evaluations,
        generations=generation_count,
        wall_time_s=wall,
        message=message,
        history=tuple(evaluator.history),
        ranked=evaluator.ranked(RANKED),
    )


def _amplitude_interval(problem: DesignProblem, best: DesignEvaluation) -> tuple[float, float]:
    """The drive amplitudes at which ``best``'s carrier meets set S and the stroke limit, within
    the bounds (homogeneity: peaks and stroke scale with ``A``); empty if ``low > high``."""
    limits, margins = problem.limits, best.margins
    variable = problem.space.variables[problem.space.names.index("drive_amplitude_n")]
    amplitude, a_s = best.params.drive_amplitude_n, margins.stick_limit_mps2
    high, low = math.inf, 0.0
    if margins.forward_peak_mps2 > 0.0:
        high = (1.0 - limits.required_margin) * a_s / margins.forward_peak_mps2
    if margins.stroke_m > 0.0:
        high = min(high, limits.max_stroke_m / margins.stroke_m)
    if margins.backward_peak_mps2 > 0.0:
        low = (1.0 + limits.required_margin) * a_s / margins.backward_peak_mps2
    else:
        low = math.inf
    # a hair inside, so that round-off cannot put the end points just outside
    low = max(amplitude * low * (1.0 + 1e-9), variable.lower)
    high = min(amplitude * high * (1.0 - 1e-9), variable.upper)
    return low, high


def _amplitude_search(problem: DesignProblem, evaluator: _Evaluator, points: int) -> None:
    """Evaluate the best design at other amplitudes (see :func:`optimize`), in batches."""
    assert evaluator.best is not None
    best = evaluator.best[0]
    low, high = _amplitude_interval(problem, best)
    if not low <= high:
        return
    space = problem.space
    column = space.names.index("drive_amplitude_n")
    centre = space.vector(best.params)

    def batch(amplitudes: F64) -> list[tuple[DesignEvaluation, F64, float]]:
        vectors = np.repeat(centre[np.newaxis, :], amplitudes.size, axis=0)
        vectors[:, column] = amplitudes
        evaluator.planned += amplitudes.size
        return evaluator.ensure(vectors.T)

    amplitudes = np.linspace(low, high, points) if high > low else np.array([low])
    entries = batch(amplitudes)
    if problem.objective != "min-force":
        return
    # min-force: refine between the smallest amplitude that meets everything and the one below
    met = [k for k, entry in enumerate(entries) if bool(np.all(entry[1] >= 0.0))]
    if met and met[0] > 0:
        k = met[0]
        batch(np.linspace(amplitudes[k - 1], amplitudes[k], points + 2)[1:-1])
