"""The design a built feeder will actually reach: a chance-constrained search over the tolerances.

The nominal search (:func:`~feeder_ros.design.optimizer.optimize`) puts its optimum on the edge
of set S: the speed rises with the drive amplitude up to the forward-stick limit. Built within its
tolerances (:class:`~feeder_ros.design.space.Tolerances`: plates, friction, part mass, drive
force), such a design misses a condition in about half the plants. This search asks instead:

* **Chance constraint.** A design is robust when every condition (set S and the validity limits)
  holds with probability at least ``p`` (``tolerances.probability``), judged from the fixed,
  seeded draws of :func:`~feeder_ros.design.robustness.drawn_plants` conservatively: the
  one-sided lower confidence bound (Clopper-Pearson, :data:`CONFIDENCE`) of the share of draws
  that meet every condition must reach ``p``. With 64 draws and ``p = 0.95`` that needs all 64:
  a share measured on 64 draws says little more.
* **Objective.** The speed that ``p`` of the built feeders reach or exceed: the ``1 - p``
  quantile of the drawn plants' speeds (max-speed only; a robust min-force search is not built).
* **Homogeneity in A, batches.** The carrier alone is positively homogeneous in the drive
  amplitude (MODEL-NOTES), so one exact run of each drawn plant gives the whole amplitude
  interval within which it meets set S and the stroke limit (as the nominal search's amplitude
  line search does for one design); the chance of every amplitude follows without another run.
  The largest amplitude meeting the chance constraint is then evaluated once more, all draws in
  one parallel batch, for the speeds. Per candidate geometry: one margins batch and one speed
  batch, where amplitude by amplitude and draw by draw would take a run for each pair.
* **Candidates.** The geometries the nominal search found best (its ranked feasible designs,
  distinct apart from the amplitude), each derated to its own robust amplitude; the best
  quantile wins. The search is deterministic: the draws are seeded, the solver exact.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.stats import beta

from feeder_ros.design.optimizer import DesignEvaluation, DesignProblem, evaluate_designs
from feeder_ros.design.robustness import drawn_plants
from feeder_ros.design.space import DesignError, Tolerances
from feeder_ros.design.stick_slip_conditions import (
    StickSlipMargins,
    condition_values,
    stick_slip_margins_many,
)
from feeder_ros.physics.parameters import FeederParameters

__all__ = [
    "CONFIDENCE",
    "RobustCandidate",
    "RobustResult",
    "amplitude_intervals",
    "chance_lower_bound",
    "robust_mask",
    "robust_search",
    "robust_text",
]

F64 = npt.NDArray[np.float64]
#: confidence of the one-sided lower bound on the share of plants meeting every condition
CONFIDENCE = 0.9
#: condition indices that scale with the drive amplitude (forward_stick, backward_slip, stroke)
_SCALING = (0, 1, 4)


def chance_lower_bound(met: int, samples: int, confidence: float = CONFIDENCE) -> float:
    """Clopper-Pearson one-sided lower bound of a share from ``met`` of ``samples`` draws."""
    if met <= 0:
        return 0.0
    return float(beta.ppf(1.0 - confidence, met, samples - met + 1))


def amplitude_intervals(
    problem: DesignProblem, params: FeederParameters, tolerances: Tolerances
) -> tuple[F64, F64, int]:
    """Per drawn plant around ``params``: the (low, high) design amplitudes [N] at which it meets
    every condition (low > high: at none), from one run of each (homogeneity in A); and the
    number of runs."""
    plants = drawn_plants(params, tolerances)
    margins = stick_slip_margins_many(plants, problem.window)
    amplitude = params.drive_amplitude_n
    lows, highs = np.empty(len(plants)), np.empty(len(plants))
    for k, (plant, found) in enumerate(zip(plants, margins, strict=True)):
        factor = plant.drive_amplitude_n / amplitude  # this plant's drive force scatter
        low, high = _force_interval(problem, found, plant.drive_amplitude_n)
        static = np.delete(condition_values(found, problem.limits), _SCALING)
        if not bool(np.all(static >= 0.0)):
            low, high = math.inf, -math.inf  # its geometry fails at every amplitude
        lows[k], highs[k] = low / factor, high / factor
    return lows, highs, len(plants)


def _force_interval(
    problem: DesignProblem, margins: StickSlipMargins, force_n: float
) -> tuple[float, float]:
    """The drive forces at which a carrier (its margins at ``force_n``) meets set S and the
    stroke limit: its peaks and stroke scale with the force."""
    limits, a_s = problem.limits, margins.stick_limit_mps2
    high = math.inf
    if margins.forward_peak_mps2 > 0.0:
        high = (1.0 - limits.required_margin) * a_s / margins.forward_peak_mps2 * force_n
    if margins.stroke_m > 0.0:
        high = min(high, limits.max_stroke_m / margins.stroke_m * force_n)
    low = math.inf
    if margins.backward_peak_mps2 > 0.0:
        low = (1.0 + limits.required_margin) * a_s / margins.backward_peak_mps2 * force_n
    return low, high


def robust_mask(
    problem: DesignProblem, designs: Sequence[FeederParameters], tolerances: Tolerances
) -> npt.NDArray[np.bool_]:
    """Which ``designs`` meet the chance constraint as they stand (at their own amplitude)."""
    out = np.zeros(len(designs), dtype=bool)
    for k, params in enumerate(designs):
        lows, highs, count = amplitude_intervals(problem, params, tolerances)
        amplitude = params.drive_amplitude_n
        met = int(np.sum((lows <= amplitude) & (amplitude <= highs)))
        out[k] = chance_lower_bound(met, count) >= tolerances.probability
    return out


@dataclass(frozen=True)
class RobustCandidate:
    """One geometry at its robust amplitude: the draws' speeds there, the share meeting every
    condition (homogeneity's prediction) and its lower bound."""

    params: FeederParameters
    met_share: float
    lower_bound: float
    speeds_mps: F64  #: the drawn plants' speeds at ``params``
    speed_quantile_mps: float  #: the ``1 - p`` quantile of ``speeds_mps``

    def record(self, problem: DesignProblem) -> dict[str, object]:
        """A JSON-ready summary: the searched variables, the share and the speed quantiles."""
        speeds = self.speeds_mps
        return {
            "variables": {name: float(getattr(self.params, name)) for name in problem.space.names},
            "share_meeting_every_condition": self.met_share,
            "share_lower_bound": self.lower_bound,
            "speed_quantile_mps": self.speed_quantile_mps,
            "speed_quantiles_mps": {f"p{q}": float(np.percentile(speeds, q)) for q in (5, 50, 95)},
        }


@dataclass(frozen=True)
class RobustResult:
    best: RobustCandidate | None  #: None: no candidate meets the chance constraint
    candidates: tuple[RobustCandidate, ...]
    tolerances: Tolerances
    runs: int  #: exact runs (margins and speeds)
    wall_time_s: float
    message: str

    @property
    def probability(self) -> float:
        return self.tolerances.probability

    def record(self, problem: DesignProblem) -> dict[str, object]:
        return {
            "probability": self.probability,
            "confidence": CONFIDENCE,
            "runs": self.runs,
            "wall_time_s": self.wall_time_s,
            "message": self.message,
            "best": None if self.best is None else self.best.record(problem),
        }


def robust_text(found: RobustResult, problem: DesignProblem, nominal_speed_mps: float) -> str:
    """The terminal lines for :func:`robust_search`'s result."""
    p = found.probability
    lines = [f"robust design (every condition with probability >= {p:g}): {found.message}"]
    best = found.best
    if best is None:
        lines.append("  none of the candidates: widen the bounds or loosen the tolerances")
        return "\n".join(lines)
    q = {f"p{k}": 1e3 * float(np.percentile(best.speeds_mps, k)) for k in (5, 50, 95)}
    for name in problem.space.names:
        lines.append(f"  {name:<22} {getattr(best.params, name):.6g}")
    lines.append(
        f"  every condition met in {100 * best.met_share:.0f} % of the drawn plants "
        f"(lower bound {100 * best.lower_bound:.1f} %)"
    )
    lines.append(
        f"  speed: {1e3 * best.speed_quantile_mps:.3g} mm/s or more in {100 * p:g} % of the "
        f"built feeders (5/50/95 %: {q['p5']:.3g}/{q['p50']:.3g}/{q['p95']:.3g} mm/s; the "
        f"nominal optimum: {1e3 * nominal_speed_mps:.3g} mm/s at its nominal values only)"
    )
    return "\n".join(lines)


def _robust_amplitude(
    problem: DesignProblem, lows: F64, highs: F64, probability: float
) -> tuple[float, int] | None:
    """The largest amplitude within the bounds whose met count's lower bound reaches
    ``probability``, with that count; None when no amplitude does."""
    variable = problem.space.variables[problem.space.names.index("drive_amplitude_n")]
    samples = lows.size
    ends = np.concatenate((highs, [variable.upper]))
    for amplitude in np.sort(ends[np.isfinite(ends)])[::-1]:
        amplitude = min(float(amplitude), variable.upper)
        if amplitude < variable.lower:
            break
        met = int(np.sum((lows <= amplitude) & (amplitude <= highs)))
        if chance_lower_bound(met, samples) >= probability:
            return amplitude, met
    return None


def _distinct_geometries(
    problem: DesignProblem, ranked: Sequence[DesignEvaluation], count: int
) -> list[FeederParameters]:
    """The first ``count`` designs of ``ranked`` that differ in more than the amplitude."""
    column = problem.space.names.index("drive_amplitude_n")
    seen: list[F64] = []
    chosen = []
    for evaluation in ranked:
        vector = np.delete(problem.space.vector(evaluation.params), column)
        if any(np.allclose(vector, other, rtol=1e-9, atol=0.0) for other in seen):
            continue
        seen.append(vector)
        chosen.append(evaluation.params)
        if len(chosen) == count:
            break
    return chosen


def robust_search(
    problem: DesignProblem,
    ranked: Sequence[DesignEvaluation],
    tolerances: Tolerances,
    candidates: int = 32,
) -> RobustResult:
    """The robust optimum among the ``candidates`` best distinct geometries of ``ranked`` (the
    nominal search's feasible designs, best first); see the module docstring."""
    if problem.objective != "max-speed":
        raise DesignError(
            f"the robust search optimises max-speed; objective {problem.objective!r} is "
            "searched at its nominal values only"
        )
    if "drive_amplitude_n" not in problem.space.names:
        raise DesignError(
            "the robust search derates the drive amplitude: variables.drive_amplitude_n is missing"
        )
    started = time.perf_counter()
    p = tolerances.probability
    runs = 0
    derated: list[tuple[FeederParameters, int]] = []
    for params in _distinct_geometries(problem, ranked, candidates):
        lows, highs, count = amplitude_intervals(problem, params, tolerances)
        runs += count
        found = _robust_amplitude(problem, lows, highs, p)
        if found is not None:
            derated.append((params.with_changes(drive_amplitude_n=found[0]), found[1]))
    plants = [plant for params, _ in derated for plant in drawn_plants(params, tolerances)]
    speeds = np.array([e.speed_mps for e in evaluate_designs(plants, problem.window, problem.part)])
    runs += len(plants)
    samples = tolerances.samples
    results = []
    for k, (params, met) in enumerate(derated):
        own = speeds[k * samples : (k + 1) * samples]
        finite = own[np.isfinite(own)]
        quantile = float(np.quantile(finite, 1.0 - p)) if finite.size == own.size else -math.inf
        results.append(
            RobustCandidate(params, met / samples, chance_lower_bound(met, samples), own, quantile)
        )
    best = max(results, key=lambda c: c.speed_quantile_mps, default=None)
    wall = time.perf_counter() - started
    message = (
        f"{len(results)} of {len(_distinct_geometries(problem, ranked, candidates))} candidate "
        f"geometries meet every condition with probability >= {p:g} ({100 * CONFIDENCE:g} % "
        f"lower bound over {samples} drawn plants); {runs} exact runs in {wall:.1f} s"
    )
    return RobustResult(best, tuple(results), tolerances, runs, wall, message)
