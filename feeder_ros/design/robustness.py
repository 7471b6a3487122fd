"""How a design fares once built: its conditions and speed over the scatter of what is not exact.

A feeder is not built at its nominal values: plates are cut to a tolerance, the friction of a part
batch is known to +-30 % at best, the drive's force to a few per cent.
:class:`~feeder_ros.design.space.Tolerances` states the scatter (each input uniform within +- a
half-width, relative or absolute; the design file's ``tolerances`` section); :func:`assess` draws a
fixed, seeded set of plants around a design,
evaluates each exactly (:func:`~feeder_ros.design.optimizer.evaluate_designs`, one parallel call)
and reports:

* the probability that each condition of set S and the validity limits holds (the share of the
  drawn plants that meet it);
* the part speed's quantiles over the drawn plants;
* the largest multiple of the tolerances (the same draws, scaled about the nominal design) within
  which every drawn plant still meets every condition: below 1 for a design that misses a
  condition somewhere within them (bisection, to 1/64), above 1 for one that holds beyond them
  (bisection up to :func:`largest_scale_tried`: 4 times, less when a relative tolerance scaled
  would reach the whole value);
* a warning for each condition the nominal design meets but a plant within the tolerances does not:
  a design that works only at its nominal values does not work.

Static and kinetic friction scatter independently; a draw whose kinetic friction would exceed its
static friction takes the static value (a part cannot slide with more friction than it sticks).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from feeder_ros.design.optimizer import DesignProblem, evaluate_designs
from feeder_ros.design.space import Tolerances
from feeder_ros.design.stick_slip_conditions import CONDITION_NAMES, condition_values
from feeder_ros.physics.parameters import FeederParameters

__all__ = [
    "MAX_SCALE",
    "Robustness",
    "assess",
    "drawn_plants",
    "largest_scale_tried",
    "robustness_text",
]

F64 = npt.NDArray[np.float64]

#: bisection steps of the largest tolerance multiple (resolution 2**-6 of the interval)
SCALE_STEPS = 6
#: the largest multiple of the tolerances tried for a design that holds within them all
MAX_SCALE = 4.0


def largest_scale_tried(tolerances: Tolerances) -> float:
    """:data:`MAX_SCALE`, or less where a relative tolerance that many times over would move a
    value by 90 % of itself or more (a friction known to +-30 %: 3 times)."""
    widest = max(tolerances.relative.values(), default=0.0)
    return MAX_SCALE if widest <= 0.0 else min(MAX_SCALE, 0.9 / widest)


def _offsets(tolerances: Tolerances) -> F64:
    """(samples, inputs) uniform draws in [-1, 1], fixed by the seed."""
    rng = np.random.default_rng(tolerances.seed)
    return rng.uniform(-1.0, 1.0, size=(tolerances.samples, len(tolerances.names)))


def drawn_plants(
    params: FeederParameters, tolerances: Tolerances, scale: float = 1.0
) -> list[FeederParameters]:
    """The drawn plants around ``params``, their scatter ``scale`` times the tolerances (the same
    draws for every scale: 0 gives the nominal design each time)."""
    offsets = _offsets(tolerances) * scale
    names = tolerances.names
    relative = len(tolerances.relative)
    widths = np.array([*tolerances.relative.values(), *tolerances.absolute.values()], np.float64)
    plants = []
    for row in offsets:
        changes: dict[str, float | int] = {}
        for k, name in enumerate(names):
            value = float(getattr(params, name))
            moved = (
                value * (1.0 + widths[k] * row[k]) if k < relative else value + widths[k] * row[k]
            )
            changes[name] = moved
        if changes.get("kinetic_friction", params.kinetic_friction) > changes.get(
            "static_friction", params.static_friction
        ):
            changes["kinetic_friction"] = changes.get("static_friction", params.static_friction)
        plants.append(params.with_changes(**changes))
    return plants


@dataclass(frozen=True)
class Robustness:
    """What :func:`assess` found for one design (see the module docstring)."""

    nominal_conditions: F64  #: each condition's value at the nominal design (>= 0: met)
    probability: F64  #: per condition: the share of drawn plants meeting it
    all_met: float  #: the share of drawn plants meeting every condition
    speed_quantiles_mps: dict[str, float]  #: "p5", "p50", "p95" over the drawn plants
    largest_scale: float  #: multiple of the tolerances within which every draw meets all
    largest_scale_tried: float  #: the most :func:`assess` tried (largest_scale at it: at least)
    samples: int
    promised: float  #: tolerances.probability
    warnings: list[str]

    @property
    def robust(self) -> bool:
        """Every condition met in at least the promised share of the drawn plants."""
        return self.all_met >= self.promised

    def record(self) -> dict[str, object]:
        """A JSON-ready summary."""
        return {
            "samples": self.samples,
            "promised_probability": self.promised,
            "probability_all_conditions": self.all_met,
            "probability_by_condition": dict(
                zip(CONDITION_NAMES, self.probability.tolist(), strict=True)
            ),
            "nominal_conditions": dict(
                zip(CONDITION_NAMES, self.nominal_conditions.tolist(), strict=True)
            ),
            "speed_quantiles_mps": self.speed_quantiles_mps,
            "largest_tolerance_multiple": self.largest_scale,
            "largest_tolerance_multiple_tried": self.largest_scale_tried,
            "robust": self.robust,
            "warnings": list(self.warnings),
        }


def _conditions(problem: DesignProblem, plants: Sequence[FeederParameters]) -> tuple[F64, F64]:
    """((samples, conditions) values, (samples,) speeds) of the drawn plants."""
    evaluations = evaluate_designs(plants, problem.window, problem.part)
    values = np.array([condition_values(e.margins, problem.limits) for e in evaluations])
    return values, np.array([e.speed_mps for e in evaluations], np.float64)


def assess(problem: DesignProblem, params: FeederParameters, tolerances: Tolerances) -> Robustness:
    """The design ``params`` (a point of ``problem``'s space, on its plant) under ``tolerances``."""
    nominal, _ = _conditions(problem, [params])
    values, speeds = _conditions(problem, drawn_plants(params, tolerances))
    met = values >= 0.0
    every = met.all(axis=1)
    largest = _largest_scale(
        problem, params, tolerances, bool(every.all()), bool(np.all(nominal >= 0))
    )
    finite = speeds[np.isfinite(speeds)]
    quantiles = (
        {f"p{q}": float(np.percentile(finite, q)) for q in (5, 50, 95)}
        if finite.size
        else {f"p{q}": math.nan for q in (5, 50, 95)}
    )
    probability = met.mean(axis=0)
    warnings = [
        f"{name} is met at the nominal values (by {nominal[0, k]:+.3g}) but only in "
        f"{100 * probability[k]:.0f} % of the plants within the tolerances"
        for k, name in enumerate(CONDITION_NAMES)
        if nominal[0, k] >= 0.0 and probability[k] < 1.0
    ]
    return Robustness(
        nominal_conditions=nominal[0],
        probability=probability,
        all_met=float(every.mean()),
        speed_quantiles_mps=quantiles,
        largest_scale=largest,
        largest_scale_tried=largest_scale_tried(tolerances),
        samples=tolerances.samples,
        promised=tolerances.probability,
        warnings=warnings,
    )


def _largest_scale(
    problem: DesignProblem,
    params: FeederParameters,
    tolerances: Tolerances,
    all_met_at_full: bool,
    nominal_met: bool,
) -> float:
    """Bisection on the tolerance multiple: every draw meets every condition below it (in [0, 1]
    when a draw misses within the tolerances, else in [1, :func:`largest_scale_tried`])."""
    if not nominal_met:
        return 0.0
    low, high = (1.0, largest_scale_tried(tolerances)) if all_met_at_full else (0.0, 1.0)
    if high <= low:
        return low
    values, _ = _conditions(problem, drawn_plants(params, tolerances, high))
    if bool(np.all(values >= 0.0)):
        return high
    for _ in range(SCALE_STEPS):
        middle = 0.5 * (low + high)
        values, _ = _conditions(problem, drawn_plants(params, tolerances, middle))
        if bool(np.all(values >= 0.0)):
            low = middle
        else:
            high = middle
    return low


def robustness_text(found: Robustness, tolerances: Tolerances, label: str = "the optimum") -> str:
    """The terminal lines for :func:`assess`'s result."""
    widths = [f"{name} +-{100 * w:g} %" for name, w in tolerances.relative.items()]
    widths += [f"{name} +-{w:g}" for name, w in tolerances.absolute.items()]
    q = found.speed_quantiles_mps
    if found.largest_scale >= found.largest_scale_tried > 1.0:
        within = f"within {found.largest_scale:.3g} times these tolerances (the most tried)"
    elif found.largest_scale > 1.0:
        within = f"within {found.largest_scale:.3g} times these tolerances"
    elif found.largest_scale == 1.0:
        within = "within these tolerances, and no wider"
    elif found.largest_scale > 0.0:
        within = f"within {100 * found.largest_scale:.3g} % of these tolerances"
    elif found.nominal_conditions.min() >= 0.0:
        within = f"within less than {100 / 2**SCALE_STEPS:.2g} % of these tolerances"
    else:
        within = "nowhere: the nominal design misses a condition"
    lines = [
        f"{label} as built: {found.samples} plants drawn (seed {tolerances.seed}) within",
        f"  {', '.join(widths)}",
        f"  every condition met in {100 * found.all_met:.0f} % of them "
        f"(a robust design: >= {100 * found.promised:g} %)",
        "  by condition: "
        + ", ".join(
            f"{name} {100 * p:.0f} %"
            for name, p in zip(CONDITION_NAMES, found.probability, strict=True)
        ),
        f"  part speed [mm/s]: {1e3 * q['p5']:.3g} (5 %), {1e3 * q['p50']:.3g} (median), "
        f"{1e3 * q['p95']:.3g} (95 %)",
        f"  every condition holds in every plant drawn {within}",
    ]
    return "\n".join(lines)
