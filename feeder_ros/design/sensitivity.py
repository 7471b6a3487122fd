"""Sensitivity of the optimum: central differences of the part speed and the set-S margins.

For each design variable the design is stepped down and up (a relative step of a continuous
variable, +-1 for ``plate_count``; a one-sided difference where a step would leave the admissible
values, e.g. ``q = 0``), everything else held, and all ``2*N`` designs are evaluated in one batch.
Reported per variable:

* the part speed (the objective of ``max-speed``; with ``min-force`` the quantity of its target
  constraint, since the amplitude itself does not move when another variable does) at both steps,
  its relative changes ``(v+- - v0)/|v0|`` and its elasticity ``(dv/v0)/(dx/x0)`` (central);
* both set-S margins at both steps and their change per relative change of the variable
  ``dm/(dx/x0)`` (the margins are already fractions of the slip threshold);
* whether each stepped design still meets every constraint.

An optimum of ``max-speed`` lies on the set-S boundary (forward margin = required margin): there
the speed rises steeply towards the boundary and drops where parts start to slip forward too, so
the one-sided changes say more than the central elasticity, and a step that leaves the feasible
set shows as ``feasible_plus``/``feasible_minus`` false. The default step is 0.5 %.

:func:`speed_map` evaluates the speed and the smallest set-S margin over a grid of two variables.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from feeder_ros.design.optimizer import DesignEvaluation, DesignProblem, evaluate_designs
from feeder_ros.design.robust_search import robust_mask
from feeder_ros.design.space import DesignError, Tolerances
from feeder_ros.physics.parameters import PARAMETER_SPECS, FeederParameters, ParameterError

__all__ = [
    "SENSITIVITY_COLUMNS",
    "SensitivityRow",
    "SpeedMap",
    "sensitivity_table",
    "speed_map",
]

F64 = npt.NDArray[np.float64]

SENSITIVITY_COLUMNS: tuple[str, ...] = (
    "variable",
    "value",
    "value_minus",
    "value_plus",
    "speed_mps",
    "speed_minus_mps",
    "speed_plus_mps",
    "speed_change_minus",
    "speed_change_plus",
    "speed_elasticity",
    "forward_margin",
    "forward_margin_minus",
    "forward_margin_plus",
    "forward_margin_slope",
    "backward_margin",
    "backward_margin_minus",
    "backward_margin_plus",
    "backward_margin_slope",
    "feasible_minus",
    "feasible_plus",
)


@dataclass(frozen=True)
class SensitivityRow:
    """One variable's row of the table (see the module docstring; columns:
    :data:`SENSITIVITY_COLUMNS`)."""

    variable: str
    value: float
    value_minus: float
    value_plus: float
    speed_mps: float
    speed_minus_mps: float
    speed_plus_mps: float
    forward_margin: float
    forward_margin_minus: float
    forward_margin_plus: float
    backward_margin: float
    backward_margin_minus: float
    backward_margin_plus: float
    feasible_minus: bool
    feasible_plus: bool

    @property
    def _relative_span(self) -> float:
        """``(x+ - x-)/|x0|`` (the absolute span for x0 = 0)."""
        span = self.value_plus - self.value_minus
        return span / abs(self.value) if self.value != 0.0 else span

    @property
    def speed_change_minus(self) -> float:
        return (self.speed_minus_mps - self.speed_mps) / abs(self.speed_mps)

    @property
    def speed_change_plus(self) -> float:
        return (self.speed_plus_mps - self.speed_mps) / abs(self.speed_mps)

    @property
    def speed_elasticity(self) -> float:
        """``((v+ - v-)/|v0|) / ((x+ - x-)/|x0|)``: % speed per % of the variable."""
        return (
            (self.speed_plus_mps - self.speed_minus_mps)
            / abs(self.speed_mps)
            / (self._relative_span)
        )

    @property
    def forward_margin_slope(self) -> float:
        return (self.forward_margin_plus - self.forward_margin_minus) / self._relative_span

    @property
    def backward_margin_slope(self) -> float:
        return (self.backward_margin_plus - self.backward_margin_minus) / self._relative_span

    def as_dict(self) -> dict[str, str | float | bool]:
        return {name: getattr(self, name) for name in SENSITIVITY_COLUMNS}


def _admissible(name: str, value: float) -> bool:
    spec = PARAMETER_SPECS[name]
    try:
        spec.check(int(value) if spec.kind is int else value)
    except ParameterError:
        return False
    return True


def _steps(name: str, value: float, relative_step: float, integer: bool) -> tuple[float, float]:
    step = 1.0 if integer else (relative_step * abs(value) if value != 0.0 else relative_step)
    low, high = value - step, value + step
    if not _admissible(name, low):
        low = value
    if not _admissible(name, high):
        high = value
    if low == high:
        raise DesignError(f"{name}={value!r}: no admissible step for a sensitivity")
    return low, high


def sensitivity_table(
    problem: DesignProblem, params: FeederParameters, relative_step: float = 0.005
) -> list[SensitivityRow]:
    """The table at ``params`` (normally the optimum) for every variable of ``problem.space``."""
    if not (math.isfinite(relative_step) and 0.0 < relative_step < 0.5):
        raise DesignError(f"relative_step={relative_step!r} must be in (0, 0.5)")
    space = problem.space
    centre = space.vector(params)
    vectors = [centre]
    steps: list[tuple[float, float]] = []
    for k, variable in enumerate(space.variables):
        low, high = _steps(variable.name, float(centre[k]), relative_step, variable.integer)
        steps.append((low, high))
        for value in (low, high):
            x = centre.copy()
            x[k] = value
            vectors.append(x)
    points = [params] + [space.to_parameters(x, params) for x in vectors[1:]]
    evaluations = evaluate_designs(points, problem.window, problem.part)
    base = evaluations[0]
    rows = []
    for k, variable in enumerate(space.variables):
        minus, plus = evaluations[1 + 2 * k], evaluations[2 + 2 * k]
        rows.append(_row(problem, variable.name, float(centre[k]), steps[k], base, minus, plus))
    return rows


def _row(
    problem: DesignProblem,
    name: str,
    value: float,
    steps: tuple[float, float],
    base: DesignEvaluation,
    minus: DesignEvaluation,
    plus: DesignEvaluation,
) -> SensitivityRow:
    return SensitivityRow(
        variable=name,
        value=value,
        value_minus=steps[0],
        value_plus=steps[1],
        speed_mps=base.speed_mps,
        speed_minus_mps=minus.speed_mps,
        speed_plus_mps=plus.speed_mps,
        forward_margin=base.margins.forward_margin,
        forward_margin_minus=minus.margins.forward_margin,
        forward_margin_plus=plus.margins.forward_margin,
        backward_margin=base.margins.backward_margin,
        backward_margin_minus=minus.margins.backward_margin,
        backward_margin_plus=plus.margins.backward_margin,
        feasible_minus=problem.feasible(minus),
        feasible_plus=problem.feasible(plus),
    )


@dataclass(frozen=True)
class SpeedMap:
    """Speed and smallest set-S margin over a grid of two variables (the others held)."""

    x_name: str
    y_name: str
    x: F64  # (nx,)
    y: F64  # (ny,)
    speed_mps: F64  # (ny, nx)
    set_s_margin: F64  # (ny, nx): min(forward, backward margin)
    feasible: npt.NDArray[np.bool_]  # (ny, nx): every constraint of the problem met
    #: (ny, nx): every condition with the promised probability within the tolerances (None: not
    #: computed)
    robust: npt.NDArray[np.bool_] | None = None


def speed_map(
    problem: DesignProblem,
    params: FeederParameters,
    x_name: str,
    y_name: str,
    points: int = 15,
    tolerances: Tolerances | None = None,
) -> SpeedMap:
    """Evaluate ``points x points`` designs over the bounds of two variables in one batch; with
    ``tolerances``, also which of them are robust
    (:func:`~feeder_ros.design.robust_search.robust_mask`)."""
    space = problem.space
    if points < 2:
        raise DesignError(f"points={points!r} must be >= 2")
    for name in (x_name, y_name):
        if name not in space.names:
            raise DesignError(f"{name!r} is not a variable of the design space")
    if x_name == y_name:
        raise DesignError(f"speed map needs two different variables (got {x_name!r} twice)")
    grids = []
    for name in (x_name, y_name):
        variable = space.variables[space.names.index(name)]
        grid = np.linspace(variable.lower, variable.upper, points)
        if variable.integer:
            grid = np.unique(np.round(grid))
        grids.append(grid)
    gx, gy = grids
    points_list = [
        params.with_changes(**{x_name: _typed(x_name, xv), y_name: _typed(y_name, yv)})
        for yv in gy
        for xv in gx
    ]
    evaluations = evaluate_designs(points_list, problem.window, problem.part)
    shape = (gy.size, gx.size)
    return SpeedMap(
        x_name=x_name,
        y_name=y_name,
        x=gx,
        y=gy,
        speed_mps=np.array([e.speed_mps for e in evaluations]).reshape(shape),
        set_s_margin=np.array(
            [min(e.margins.forward_margin, e.margins.backward_margin) for e in evaluations]
        ).reshape(shape),
        feasible=np.array([problem.feasible(e) for e in evaluations]).reshape(shape),
        robust=(
            None
            if tolerances is None
            else robust_mask(problem, points_list, tolerances).reshape(shape)
        ),
    )


def _typed(name: str, value: float) -> float | int:
    return int(np.rint(value)) if PARAMETER_SPECS[name].kind is int else float(value)
