"""The paper's stick-slip conditions (set S) and the design's validity limits, as signed margins.

The conclusion of the paper states when a part advances by stick-slip: the carrier's acceleration in
the forward direction stays below the slip threshold ``a_s = mu_s*g*kappa`` (Eq. 11: the part
*sticks* and is dragged forward), and its backward acceleration exceeds it (the carrier is pulled
back under the part, which *slips*). Both are read here on the carrier's **steady-state** motion,
the window ``[settle_s, settle_s + window_s]`` after the start-up transient (with viscous damping
``c`` the transient decays as ``exp(-c*t/(2*M_eq))``):

* ``forward_margin = 1 - a_fwd/a_s`` with ``a_fwd = max x''`` over the window (> 0: parts stick
  while the carrier accelerates forward);
* ``backward_margin = a_bwd/a_s - 1`` with ``a_bwd = max(-x'')`` (> 0: parts slip when it
  accelerates backward).

Both are signed fractions of the threshold. The physical-validity limits that the design search
needs besides set S, written the same way (``value/limit - 1 >= 0`` when met):

* ``stiffness_ratio``: ``K_f/K_b = (L_b/L_f)^3`` at least ``min_stiffness_ratio`` (the bracket makes
  the forward bending stiffer, Fig. 4; a ratio of 1 is a symmetric spring, no stick-slip drive);
* ``slenderness``: ``min(L_f, L_b)/h`` at least ``min_slenderness`` (Eq. 1 is Euler-Bernoulli
  cantilever stiffness, valid for slender plates);
* ``stroke``: the peak-to-peak carrier displacement over the window at most ``max_stroke_m``
  (Eq. 1 is a small-deflection stiffness; feeders run at strokes of a few mm at most):
  ``1 - stroke/max_stroke_m``.

The peaks are read from the exact solution (:class:`~feeder_ros.physics.simulation.FeederSimulator`,
carrier only) sampled at ``margin_rate_hz`` and refined by the parabola through the largest sample
and its neighbours (the acceleration is continuous with displacement switching; the refinement
makes the peak's error fourth order in the sample spacing away from a stiffness switch).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.parameters import FeederParameters, ParameterError, finite_number
from feeder_ros.physics.simulation import FeederSimulator

__all__ = [
    "CONDITION_NAMES",
    "ConditionLimits",
    "EvaluationWindow",
    "StickSlipMargins",
    "condition_values",
    "peak_with_refinement",
    "stick_slip_margins",
    "stick_slip_margins_many",
]

F64 = npt.NDArray[np.float64]

#: the conditions, in the order of :func:`condition_values` (each >= 0 when met)
CONDITION_NAMES: tuple[str, ...] = (
    "forward_stick",
    "backward_slip",
    "stiffness_ratio",
    "slenderness",
    "stroke",
)


@dataclass(frozen=True)
class EvaluationWindow:
    """When a design is measured: after ``settle_s`` (start-up transient), for ``window_s``.

    ``margin_rate_hz`` is the sample rate of the carrier acceleration read for the margins.
    """

    settle_s: float = 1.0
    window_s: float = 1.0
    margin_rate_hz: float = 20000.0

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "settle_s", finite_number("settle_s", self.settle_s, nonnegative=True)
        )
        object.__setattr__(
            self, "window_s", finite_number("window_s", self.window_s, positive=True)
        )
        rate = finite_number("margin_rate_hz", self.margin_rate_hz, positive=True)
        if rate * self.window_s < 10.0:
            raise ParameterError(
                f"margin_rate_hz={self.margin_rate_hz!r} gives fewer than 10 samples in "
                f"window_s={self.window_s!r}"
            )
        object.__setattr__(self, "margin_rate_hz", rate)

    def transient_left(self, params: FeederParameters) -> float:
        """Fraction of the start-up transient left at ``settle_s``: ``exp(-c*t/(2*M_eq))``."""
        return math.exp(
            -params.damping_ns_per_m * self.settle_s / (2.0 * params.equivalent_mass_kg)
        )


@dataclass(frozen=True)
class ConditionLimits:
    """Required margins of set S and the validity limits (see the module docstring)."""

    required_margin: float = 0.05  # both set-S margins at least this (friction scatter)
    min_stiffness_ratio: float = 1.5
    min_slenderness: float = 5.0
    max_stroke_m: float = 0.005

    def __post_init__(self) -> None:
        margin = finite_number("required_margin", self.required_margin, nonnegative=True)
        if margin >= 1.0:
            raise ParameterError(f"required_margin={self.required_margin!r} must be < 1")
        object.__setattr__(self, "required_margin", margin)
        ratio = finite_number("min_stiffness_ratio", self.min_stiffness_ratio, positive=True)
        object.__setattr__(self, "min_stiffness_ratio", ratio)
        slender = finite_number("min_slenderness", self.min_slenderness, positive=True)
        object.__setattr__(self, "min_slenderness", slender)
        stroke = finite_number("max_stroke_m", self.max_stroke_m, positive=True)
        object.__setattr__(self, "max_stroke_m", stroke)


@dataclass(frozen=True)
class StickSlipMargins:
    """Steady-state carrier peaks of one design and its set-S margins."""

    stick_limit_mps2: float  # a_s = mu_s*g*kappa (Eq. 11)
    forward_peak_mps2: float  # max x'' over the window
    backward_peak_mps2: float  # max -x'' over the window
    stroke_m: float  # max x - min x over the window
    stiffness_ratio: float  # K_f/K_b
    slenderness: float  # min(L_f, L_b)/h

    @property
    def forward_margin(self) -> float:
        """``1 - a_fwd/a_s``: > 0 when parts stick while the carrier accelerates forward."""
        return 1.0 - self.forward_peak_mps2 / self.stick_limit_mps2

    @property
    def backward_margin(self) -> float:
        """``a_bwd/a_s - 1``: > 0 when parts slip while the carrier accelerates backward."""
        return self.backward_peak_mps2 / self.stick_limit_mps2 - 1.0

    def in_set_s(self, required_margin: float = 0.0) -> bool:
        """Both conditions of set S met with at least ``required_margin``."""
        return min(self.forward_margin, self.backward_margin) >= required_margin


def peak_with_refinement(values: F64) -> float:
    """The largest value of a smooth sampled signal: the vertex of the parabola through the
    largest sample and its two neighbours (the sample itself at either end, or if the three
    points do not bend down)."""
    if values.size == 0:
        raise ParameterError("no samples to take a peak of")
    k = int(np.argmax(values))
    best = float(values[k])
    if 0 < k < values.size - 1:
        y0, y1, y2 = float(values[k - 1]), best, float(values[k + 1])
        bend = y0 - 2.0 * y1 + y2
        if bend < 0.0:
            best = max(best, y1 - (y2 - y0) ** 2 / (8.0 * bend))
    return best


def _window_samples(window: EvaluationWindow) -> F64:
    n = math.floor(window.window_s * window.margin_rate_hz * (1.0 + 1e-12))
    return window.settle_s + np.arange(n + 1, dtype=np.float64) / window.margin_rate_hz


def stick_slip_margins(
    params: FeederParameters, window: EvaluationWindow | None = None
) -> StickSlipMargins:
    """The set-S margins of one design from its exact carrier motion in ``window`` (default:
    :class:`EvaluationWindow`)."""
    window = window if window is not None else EvaluationWindow()
    samples = _window_samples(window)
    simulator = FeederSimulator(params, parts=())
    if window.settle_s > 0.0:
        simulator.advance(window.settle_s)
    result = simulator.advance(float(samples[-1]), samples)
    a = result.carrier_a_mps2
    x = result.carrier_x_m
    return StickSlipMargins(
        stick_limit_mps2=params.stick_limit_mps2,
        forward_peak_mps2=peak_with_refinement(a),
        backward_peak_mps2=peak_with_refinement(-a),
        stroke_m=peak_with_refinement(x) + peak_with_refinement(-x),
        stiffness_ratio=params.forward_stiffness_n_per_m / params.backward_stiffness_n_per_m,
        slenderness=min(params.forward_length_m, params.backward_length_m)
        / params.plate_thickness_m,
    )


def stick_slip_margins_many(
    points: Sequence[FeederParameters], window: EvaluationWindow | None = None
) -> list[StickSlipMargins]:
    """:func:`stick_slip_margins` of each design (the carrier solver runs about 1 ms per design
    and simulated second at 20 kHz output)."""
    return [stick_slip_margins(params, window) for params in points]


def condition_values(margins: StickSlipMargins, limits: ConditionLimits) -> F64:
    """The conditions of :data:`CONDITION_NAMES` as fractions, each >= 0 when met."""
    return np.array(
        [
            margins.forward_margin - limits.required_margin,
            margins.backward_margin - limits.required_margin,
            margins.stiffness_ratio / limits.min_stiffness_ratio - 1.0,
            margins.slenderness / limits.min_slenderness - 1.0,
            1.0 - margins.stroke_m / limits.max_stroke_m,
        ],
        dtype=np.float64,
    )
