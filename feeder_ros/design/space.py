"""The carrier's design space: variables, bounds, integrality, and the design YAML file.

A design is a vector over :attr:`DesignSpace.names` (a subset of :data:`DESIGN_VARIABLES`, in that
order); :meth:`DesignSpace.to_parameters` puts it into a plant's
:class:`~feeder_ros.physics.parameters.FeederParameters` (every other parameter, e.g. masses,
friction, damping, stays the plant's). ``plate_count`` is an integer variable.

The design file (``config/design.yaml``) has four sections, each optional except ``variables``::

    variables:   {name: [lower, upper]}          # searched; leave one out to keep the plant's value
    conditions:  {required_margin: 0.05, ...}    # ConditionLimits (set S margins, validity)
    evaluation:  {settle_s: 1.0, ...}            # EvaluationWindow (steady-state window)
    reference:   {name: value}                   # the design to compare with (the case study)

Errors name the key and the value (``variables.plate_count: lower bound 1.5 is not an integer``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from feeder_ros.design.stick_slip_conditions import ConditionLimits, EvaluationWindow
from feeder_ros.physics.parameters import (
    PARAMETER_SPECS,
    FeederParameters,
    ParameterError,
    is_number,
)
from feeder_ros.yaml_files import YamlFileError, read_yaml

__all__ = [
    "DESIGN_VARIABLES",
    "DesignConfig",
    "DesignError",
    "DesignSpace",
    "DesignVariable",
    "Tolerances",
    "load_design_config",
]

F64 = npt.NDArray[np.float64]

#: the searchable parameters (FeederParameters names), in vector order
DESIGN_VARIABLES: tuple[str, ...] = (
    "forward_length_m",
    "backward_length_m",
    "plate_thickness_m",
    "plate_count",
    "plate_angle_deg",
    "drive_frequency_hz",
    "drive_amplitude_n",
)
_SECTIONS = ("variables", "conditions", "evaluation", "reference", "tolerances")


class DesignError(ParameterError):
    """A design space or design file the search cannot use; the message names key and value."""


def _bound(key: str, which: str, value: object, integer: bool) -> float:
    if not is_number(value):
        raise DesignError(f"{key}: {which} bound {value!r} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise DesignError(f"{key}: {which} bound {value!r} is not finite")
    if integer and number != math.floor(number):
        raise DesignError(f"{key}: {which} bound {value!r} is not an integer")
    return number


@dataclass(frozen=True)
class DesignVariable:
    """One searched parameter with its bounds ``lower < upper`` (both admissible values)."""

    name: str
    lower: float
    upper: float

    def __post_init__(self) -> None:
        if self.name not in DESIGN_VARIABLES:
            raise DesignError(
                f"unknown design variable {self.name!r}; known: {', '.join(DESIGN_VARIABLES)}"
            )
        key = f"variables.{self.name}"
        lower = _bound(key, "lower", self.lower, self.integer)
        upper = _bound(key, "upper", self.upper, self.integer)
        if lower >= upper:
            raise DesignError(
                f"{key}: lower bound {self.lower!r} must be below the upper bound {self.upper!r}"
                + (" (to fix a value, leave the variable out and set it on the plant)")
                * (lower == upper)
            )
        spec = PARAMETER_SPECS[self.name]
        for which, value in (("lower", lower), ("upper", upper)):
            try:
                spec.check(int(value) if self.integer else value)
            except ParameterError as error:
                raise DesignError(f"{key}: {which} bound: {error}") from None
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    @property
    def integer(self) -> bool:
        return PARAMETER_SPECS[self.name].kind is int

    @property
    def unit(self) -> str:
        return PARAMETER_SPECS[self.name].unit


@dataclass(frozen=True)
class DesignSpace:
    """The searched variables, in :data:`DESIGN_VARIABLES` order whatever order they come in."""

    variables: tuple[DesignVariable, ...]

    def __post_init__(self) -> None:
        if not self.variables:
            raise DesignError(
                f"variables: no design variable given; known: {', '.join(DESIGN_VARIABLES)}"
            )
        names = [v.name for v in self.variables]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise DesignError(f"variables: {', '.join(repeated)} given more than once")
        ordered = tuple(sorted(self.variables, key=lambda v: DESIGN_VARIABLES.index(v.name)))
        object.__setattr__(self, "variables", ordered)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> DesignSpace:
        """``{name: [lower, upper]}`` (or ``{name: {lower: .., upper: ..}}``)."""
        if not isinstance(values, Mapping):
            raise DesignError(f"variables: expected name: [lower, upper], got {values!r}")
        variables = []
        for name, bounds in values.items():
            key = f"variables.{name}"
            if str(name) not in DESIGN_VARIABLES:
                raise DesignError(
                    f"{key}: unknown design variable {name!r}; known: {', '.join(DESIGN_VARIABLES)}"
                )
            if isinstance(bounds, Mapping) and set(bounds) == {"lower", "upper"}:
                pair: Sequence[Any] = (bounds["lower"], bounds["upper"])
            elif isinstance(bounds, Sequence) and not isinstance(bounds, str) and len(bounds) == 2:
                pair = bounds
            else:
                raise DesignError(f"{key}: expected [lower, upper], got {bounds!r}")
            variables.append(DesignVariable(str(name), pair[0], pair[1]))
        return cls(tuple(variables))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables)

    @property
    def size(self) -> int:
        return len(self.variables)

    @property
    def lower(self) -> F64:
        return np.array([v.lower for v in self.variables], dtype=np.float64)

    @property
    def upper(self) -> F64:
        return np.array([v.upper for v in self.variables], dtype=np.float64)

    @property
    def integrality(self) -> npt.NDArray[np.bool_]:
        return np.array([v.integer for v in self.variables], dtype=np.bool_)

    def contains(self, vector: npt.ArrayLike) -> bool:
        x = np.asarray(vector, dtype=np.float64)
        return bool(np.all(x >= self.lower) and np.all(x <= self.upper))

    def to_parameters(self, vector: npt.ArrayLike, plant: FeederParameters) -> FeederParameters:
        """The plant with the design ``vector`` put in (integer variables rounded)."""
        x = np.asarray(vector, dtype=np.float64).ravel()
        if x.size != self.size:
            raise DesignError(
                f"design vector has {x.size} values; the space has {self.size} "
                f"({', '.join(self.names)})"
            )
        changes: dict[str, float | int] = {}
        for variable, value in zip(self.variables, x, strict=True):
            changes[variable.name] = int(np.rint(value)) if variable.integer else float(value)
        return plant.with_changes(**changes)

    def vector(self, params: FeederParameters) -> F64:
        """The design vector of ``params``."""
        return np.array([float(getattr(params, name)) for name in self.names], dtype=np.float64)


#: scatter of a built feeder by default: +- half-widths, relative (fraction of the value)
DEFAULT_RELATIVE = {
    "forward_length_m": 0.01,
    "backward_length_m": 0.01,
    "plate_thickness_m": 0.01,
    "static_friction": 0.30,
    "kinetic_friction": 0.30,
    "part_mass_kg": 0.05,
    "drive_amplitude_n": 0.03,
}
#: ... and absolute (in the parameter's unit)
DEFAULT_ABSOLUTE = {"plate_angle_deg": 0.5}


@dataclass(frozen=True)
class Tolerances:
    """Uniform scatter of the inputs: ``relative`` (+- fraction of the value) and ``absolute``
    (+- in the parameter's unit) half-widths by parameter name; ``samples`` plants drawn with
    ``seed``; ``probability``: the share of plants a robust design must meet every condition in
    (reported against)."""

    relative: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_RELATIVE))
    absolute: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_ABSOLUTE))
    samples: int = 64
    seed: int = 1
    probability: float = 0.95

    def __post_init__(self) -> None:
        for kind, table in (("relative", self.relative), ("absolute", self.absolute)):
            if not isinstance(table, Mapping):
                raise DesignError(f"{kind}: expected name: half-width, got {table!r}")
            for name, value in table.items():
                if name not in PARAMETER_SPECS or PARAMETER_SPECS[name].kind is not float:
                    raise DesignError(f"{kind}: {name!r} is not a real-valued parameter")
                ok = is_number(value) and math.isfinite(value) and value >= 0.0
                if not ok or (kind == "relative" and value >= 1.0):
                    limit = "in [0, 1)" if kind == "relative" else "finite and >= 0"
                    raise DesignError(f"{kind}.{name}={value!r} must be {limit}")
        both = sorted(set(self.relative) & set(self.absolute))
        if both:
            raise DesignError(f"{', '.join(both)} both relative and absolute")
        if not (isinstance(self.samples, int) and 8 <= self.samples <= 10_000):
            raise DesignError(f"samples={self.samples!r} must be an integer in [8, 10000]")
        if not isinstance(self.seed, int):
            raise DesignError(f"seed={self.seed!r} must be an integer")
        p = self.probability
        if not (is_number(p) and 0.0 < p <= 1.0):
            raise DesignError(f"probability={p!r} must be in (0, 1]")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.relative) + tuple(self.absolute)


@dataclass(frozen=True)
class DesignConfig:
    """A design file: the space, the condition limits, the evaluation window, the reference, the
    tolerances a built feeder scatters within."""

    space: DesignSpace
    limits: ConditionLimits = field(default_factory=ConditionLimits)
    window: EvaluationWindow = field(default_factory=EvaluationWindow)
    reference: Mapping[str, float | int | str] = field(default_factory=dict)
    tolerances: Tolerances = field(default_factory=lambda: Tolerances())

    @classmethod
    def from_mapping(cls, document: Mapping[str, Any], source: str = "design") -> DesignConfig:
        if not isinstance(document, Mapping):
            raise DesignError(f"{source}: expected sections {', '.join(_SECTIONS)}")
        unknown = sorted(str(key) for key in document if key not in _SECTIONS)
        if unknown:
            raise DesignError(
                f"{source}: unknown section {', '.join(unknown)}; known: {', '.join(_SECTIONS)}"
            )
        if "variables" not in document:
            raise DesignError(f"{source}: no 'variables' section")
        space = DesignSpace.from_mapping(document["variables"])
        limits = _settings(ConditionLimits, document.get("conditions"), "conditions")
        window = _settings(EvaluationWindow, document.get("evaluation"), "evaluation")
        reference = document.get("reference") or {}
        if not isinstance(reference, Mapping):
            raise DesignError(f"reference: expected name: value, got {reference!r}")
        try:
            FeederParameters.from_mapping(reference)
        except ParameterError as error:
            raise DesignError(f"reference: {error}") from None
        tolerances = _settings(Tolerances, document.get("tolerances"), "tolerances")
        return cls(space, limits, window, dict(reference), tolerances)

    def reference_parameters(self, plant: FeederParameters) -> FeederParameters:
        """The plant with the reference design put in."""
        return plant.with_changes(**self.reference)


def _settings(kind: type[Any], values: object, section: str) -> Any:
    if values is None:
        return kind()
    if not isinstance(values, Mapping):
        raise DesignError(f"{section}: expected name: value, got {values!r}")
    known = kind.__dataclass_fields__
    unknown = sorted(str(key) for key in values if key not in known)
    if unknown:
        raise DesignError(f"{section}: unknown key {', '.join(unknown)}; known: {', '.join(known)}")
    try:
        return kind(**values)
    except ParameterError as error:
        raise DesignError(f"{section}.{error}") from None


def load_design_config(path: Path) -> DesignConfig:
    """Read a design file; errors name the file, the key and the value."""
    try:
        document = read_yaml(path)
    except YamlFileError as error:
        raise DesignError(str(error)) from None
    try:
        return DesignConfig.from_mapping(document, str(path))
    except DesignError as error:
        message = str(error)  # the file named once
        if not message.startswith(f"{path}:"):
            message = f"{path}: {message}"
        raise DesignError(message) from None
