"""Physical parameters of the inline feeder (paper Sections 3-4): public names, units, limits.

One table, :data:`PARAMETER_SPECS`, is the single source of the public names: the YAML files in
``config/``, the ROS parameters of the nodes and ``feeder sim --set`` all use it. Every value is SI.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, Final, TypeGuard

import numpy as np

__all__ = [
    "MAX_NATURAL_FREQUENCY_HZ",
    "PARAMETER_SPECS",
    "FeederParameters",
    "ParameterError",
    "ParameterSpec",
    "finite_number",
    "is_number",
    "parse_parameter_value",
]


#: the highest natural frequency of the carrier accepted [Hz]: far above any vibratory feeder,
#: and where the event solver still resolves a period at t = 1e4 s (double precision)
MAX_NATURAL_FREQUENCY_HZ: Final = 1e6


class ParameterError(ValueError):
    """A parameter name or value that the model cannot accept; the message names the value."""


def is_number(value: object) -> TypeGuard[float]:
    """A real number: Python's or NumPy's scalars (np.float32, np.int64, ...), not a bool; it
    converts and compares like a float."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def finite_number(
    name: str, value: object, *, positive: bool = False, nonnegative: bool = False
) -> float:
    """``value`` as a finite float; ParameterError naming ``name`` and the value otherwise."""
    if not is_number(value):
        raise ParameterError(f"{name}={value!r} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise ParameterError(f"{name}={value!r} is not finite")
    if positive and number <= 0.0:
        raise ParameterError(f"{name}={value!r} must be > 0")
    if nonnegative and number < 0.0:
        raise ParameterError(f"{name}={value!r} must be >= 0")
    return number


@dataclass(frozen=True)
class ParameterSpec:
    """Name, unit, meaning and admissible range of one public parameter."""

    name: str
    kind: type  # float, int, bool or str
    unit: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    choices: tuple[str, ...] = ()  # for str: the allowed values; empty: any string
    read_only: bool = False  # fixed for the life of a running simulator node
    nan_allowed: bool = False  # for float: NaN means "not set" (e.g. no target speed)

    @property
    def _unit(self) -> str:
        """The unit after a value in a message (none for a pure number, unit "1")."""
        return "" if self.unit in ("", "1") else f" {self.unit}"

    def check(self, value: object) -> float | int | bool | str:
        """Return ``value`` converted to this parameter's type, or raise :class:`ParameterError`."""
        if self.kind is bool:
            if not isinstance(value, bool):
                raise ParameterError(f"{self.name}={value!r} is not true or false")
            return value
        if self.kind is str:
            if self.choices and not (isinstance(value, str) and value in self.choices):
                raise ParameterError(
                    f"{self.name}={value!r} is not one of {', '.join(self.choices)}"
                )
            if not isinstance(value, str):
                raise ParameterError(f"{self.name}={value!r} is not a string")
            return value
        if not is_number(value):
            raise ParameterError(f"{self.name}={value!r} is not a number")
        real = float(value)
        if self.kind is int:
            if not math.isfinite(real) or real != int(real):
                raise ParameterError(f"{self.name}={value!r} is not an integer")
            number: float | int = int(real)
        else:
            number = real
        if math.isnan(number) and self.nan_allowed:
            return number
        if not math.isfinite(number):
            raise ParameterError(f"{self.name}={value!r} is not finite")
        if self.minimum is not None:
            below = number <= self.minimum if self.exclusive_minimum else number < self.minimum
            if below:
                raise ParameterError(f"{self.name}={value!r}{self._unit} must be {self._lower}")
        if self.maximum is not None and number > self.maximum:
            raise ParameterError(f"{self.name}={value!r}{self._unit} must be {self._upper}")
        return number

    @property
    def _lower(self) -> str:
        """The lower bound as declared, with its unit: ">= 5 Hz", "> 0 kg"."""
        relation = ">" if self.exclusive_minimum else ">="
        return f"{relation} {self.minimum:g}{self._unit}"

    @property
    def _upper(self) -> str:
        return f"<= {self.maximum:g}{self._unit}"

    @property
    def bounds(self) -> str:
        """The admissible range as declared, for messages and descriptions: ">= 5 Hz",
        "<= 300 Hz", "from 5 to 300 Hz", "> 0 and <= 100 %"; "" for a parameter without bounds."""
        if self.minimum is None:
            return "" if self.maximum is None else self._upper
        if self.maximum is None:
            return self._lower
        if self.exclusive_minimum:
            return f"> {self.minimum:g} and <= {self.maximum:g}{self._unit}"
        return f"from {self.minimum:g} to {self.maximum:g}{self._unit}"


def _positive(name: str, unit: str, description: str, read_only: bool = True) -> ParameterSpec:
    return ParameterSpec(
        name, float, unit, description, minimum=0.0, exclusive_minimum=True, read_only=read_only
    )


PARAMETER_SPECS: Final[dict[str, ParameterSpec]] = {
    spec.name: spec
    for spec in (
        ParameterSpec(
            "plate_angle_deg",
            float,
            "deg",
            "leaf-spring angle theta to the vertical axis (paper Eq. 3)",
            minimum=0.0,
            maximum=89.9,
            read_only=True,
        ),
        _positive("plate_mass_kg", "kg", "mass m of the leaf-spring plate"),
        # stiffness and load may drift on a running feeder (spring ageing, tooling, parts): the
        # simulator node applies them live, the carrier state carrying over (resonance tracking)
        _positive(
            "carrier_mass_kg", "kg", "mass M of the carrier (vibrating beam)", read_only=False
        ),
        _positive(
            "part_mass_kg", "kg", "mass M_p of a part (the paper's vehicle)", read_only=False
        ),
        _positive("youngs_modulus_pa", "Pa", "Young's modulus E of the plate", read_only=False),
        _positive("forward_length_m", "m", "effective plate length L_f when bending forward"),
        _positive("backward_length_m", "m", "effective plate length L_b when bending backward"),
        _positive("plate_width_m", "m", "plate width w"),
        _positive("plate_thickness_m", "m", "plate thickness h"),
        ParameterSpec(
            "plate_count", int, "1", "number q of stacked plates", minimum=1, read_only=True
        ),
        ParameterSpec(
            "mass_coefficient",
            float,
            "1",
            "effective-mass coefficient alpha of the plate (33/144 for a cantilever)",
            minimum=0.0,
            maximum=1.0,
            read_only=True,
        ),
        ParameterSpec(
            "damping_ns_per_m",
            float,
            "N*s/m",
            "viscous damping c of the carrier (0 reproduces the paper)",
            minimum=0.0,
        ),
        ParameterSpec(
            "stiffness_switch",
            str,
            "",
            "stiffness branch selected by the sign of displacement (Eq. 7) or velocity (Fig. 6)",
            choices=("displacement", "velocity"),
            read_only=True,
        ),
        ParameterSpec(
            "stiffness_model",
            str,
            "",
            "sharp switch (Eq. 7, exact event-driven solution) or logistic (Eq. 9, ODE solver)",
            choices=("sharp", "logistic"),
            read_only=True,
        ),
        _positive("logistic_beta_per_m", "1/m", "sharpness beta of the logistic switch (Eq. 9)"),
        _positive("static_friction", "1", "static friction coefficient mu_s", read_only=False),
        _positive("kinetic_friction", "1", "kinetic friction coefficient mu_d", read_only=False),
        ParameterSpec(
            "groove_angle_deg",
            float,
            "deg",
            "included V-groove angle; 180 is flat (friction multiplier 1/sin(angle/2))",
            minimum=0.0,
            maximum=180.0,
            exclusive_minimum=True,
        ),
        _positive("gravity_mps2", "m/s^2", "gravitational acceleration g"),
        ParameterSpec(
            "drive_frequency_hz",
            float,
            "Hz",
            "drive force frequency f_d",
            minimum=0.0,
            exclusive_minimum=True,
        ),
        ParameterSpec("drive_amplitude_n", float, "N", "drive force amplitude A", minimum=0.0),
        ParameterSpec(
            "coupling",
            str,
            "",
            "one_way: parts do not act on the carrier; two_way: slip friction acts on it (Eq. 14)",
            choices=("one_way", "two_way"),
            read_only=True,
        ),
        _positive(
            "track_length_m", "m", "track length; a part past it leaves the feeder", read_only=False
        ),
    )
}


@dataclass(frozen=True)
class FeederParameters:
    """The feeder model's parameters, validated on construction. Defaults: the paper's case study.

    The paper prints ``M_p = 50 kg`` but its natural frequencies need ``0.05 kg`` (MODEL-NOTES).
    """

    plate_angle_deg: float = 80.0
    plate_mass_kg: float = 0.4
    carrier_mass_kg: float = 10.0
    part_mass_kg: float = 0.05
    youngs_modulus_pa: float = 200e9
    forward_length_m: float = 0.05
    backward_length_m: float = 0.15
    plate_width_m: float = 0.05
    plate_thickness_m: float = 0.005
    plate_count: int = 1
    mass_coefficient: float = 33.0 / 144.0
    damping_ns_per_m: float = 0.0
    stiffness_switch: str = "displacement"
    stiffness_model: str = "sharp"
    logistic_beta_per_m: float = 1e6
    static_friction: float = 0.2
    kinetic_friction: float = 0.1
    groove_angle_deg: float = 180.0
    gravity_mps2: float = 9.81
    drive_frequency_hz: float = 29.6
    drive_amplitude_n: float = 0.4
    coupling: str = "one_way"
    track_length_m: float = 0.5

    def __post_init__(self) -> None:
        for field in fields(self):
            checked = PARAMETER_SPECS[field.name].check(getattr(self, field.name))
            object.__setattr__(self, field.name, checked)
        if self.kinetic_friction > self.static_friction:
            raise ParameterError(
                f"kinetic_friction={self.kinetic_friction!r} must not exceed "
                f"static_friction={self.static_friction!r}"
            )
        for side in ("forward", "backward"):
            self._check_natural_frequency(side)

    def _check_natural_frequency(self, side: str) -> None:
        """Each value may be in range while together they give a stiffness that overflows or
        vanishes (L_f = 1e-60 m: K_f ~ 1e180 N/m): refuse what the solver cannot resolve."""
        length = getattr(self, f"{side}_length_m")
        try:
            frequency = getattr(self, f"{side}_natural_frequency_hz")
        except (ZeroDivisionError, OverflowError):
            frequency = math.inf
        if math.isfinite(frequency) and 0.0 < frequency <= MAX_NATURAL_FREQUENCY_HZ:
            return
        raise ParameterError(
            f"{side}_length_m={length!r} with youngs_modulus_pa={self.youngs_modulus_pa!r}, "
            f"plate_width_m={self.plate_width_m!r}, plate_thickness_m={self.plate_thickness_m!r}, "
            f"plate_count={self.plate_count!r} and the masses gives a {side} natural frequency "
            f"of {frequency:.3g} Hz: it must be > 0 and at most {MAX_NATURAL_FREQUENCY_HZ:g} Hz"
        )

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_mapping(
        cls, values: Mapping[str, Any], base: FeederParameters | None = None
    ) -> FeederParameters:
        """Parameters from a name->value mapping (YAML, ROS parameters); unknown names refused."""
        unknown = sorted(set(values) - set(PARAMETER_SPECS))
        if unknown:
            raise ParameterError(
                f"unknown parameter {', '.join(unknown)}; known: {', '.join(PARAMETER_SPECS)}"
            )
        return replace(base if base is not None else cls(), **dict(values))

    def with_changes(self, **changes: Any) -> FeederParameters:
        """A validated copy with some values changed."""
        return self.from_mapping(changes, base=self)

    def as_dict(self) -> dict[str, float | int | str]:
        return {field.name: getattr(self, field.name) for field in fields(self)}

    # -- derived quantities (paper Eqs. 1-5, 11) ----------------------------------------------
    @property
    def second_moment_m4(self) -> float:
        """I = q*w*h^3/12 of the plate stack."""
        return self.plate_count * self.plate_width_m * self.plate_thickness_m**3 / 12.0

    @property
    def forward_stiffness_n_per_m(self) -> float:
        """K_f = 3*E*I/L_f^3 (Eq. 1 with L = L_f)."""
        return 3.0 * self.youngs_modulus_pa * self.second_moment_m4 / self.forward_length_m**3

    @property
    def backward_stiffness_n_per_m(self) -> float:
        """K_b = 3*E*I/L_b^3."""
        return 3.0 * self.youngs_modulus_pa * self.second_moment_m4 / self.backward_length_m**3

    @property
    def equivalent_mass_kg(self) -> float:
        """M_eq = M + M_p + alpha*m (Eq. 2); with one-way coupling the part rides in M_eq."""
        return self.carrier_mass_kg + self.part_mass_kg + self.mass_coefficient * self.plate_mass_kg

    @property
    def cos_theta(self) -> float:
        return math.cos(math.radians(self.plate_angle_deg))

    @property
    def forward_natural_frequency_hz(self) -> float:
        """omega_f/(2*pi) with omega_f = sqrt(K_f*cos(theta)/M_eq) (Eq. 5)."""
        omega = math.sqrt(self.forward_stiffness_n_per_m * self.cos_theta / self.equivalent_mass_kg)
        return omega / (2.0 * math.pi)

    @property
    def backward_natural_frequency_hz(self) -> float:
        omega = math.sqrt(
            self.backward_stiffness_n_per_m * self.cos_theta / self.equivalent_mass_kg
        )
        return omega / (2.0 * math.pi)

    @property
    def friction_multiplier(self) -> float:
        """kappa = 1/sin(groove/2): a V-groove raises the normal force; 1 on a flat track."""
        return 1.0 / math.sin(math.radians(self.groove_angle_deg) / 2.0)

    @property
    def stick_limit_mps2(self) -> float:
        """Largest carrier acceleration a sticking part can follow: mu_s*g*kappa (Eq. 11)."""
        return self.static_friction * self.gravity_mps2 * self.friction_multiplier

    @property
    def slip_deceleration_mps2(self) -> float:
        """Magnitude of a slipping part's acceleration: mu_d*g*kappa."""
        return self.kinetic_friction * self.gravity_mps2 * self.friction_multiplier


def parse_parameter_value(name: str, text: str) -> float | int | bool | str:
    """Parse ``text`` (e.g. from ``--set name=value``) as the value of parameter ``name``."""
    spec = PARAMETER_SPECS.get(name)
    if spec is None:
        raise ParameterError(f"unknown parameter {name!r}; known: {', '.join(PARAMETER_SPECS)}")
    if spec.kind is str:
        return spec.check(text)
    if spec.kind is bool:
        words = {"true": True, "false": False}
        if text.strip().lower() not in words:
            raise ParameterError(f"{name}={text!r} is not true or false")
        return words[text.strip().lower()]
    try:
        number = float(text)
    except ValueError:
        raise ParameterError(f"{name}={text!r} is not a number") from None
    return spec.check(number)
