"""The estimator's records and settings (ROS-free): status codes, configuration, the published
record and the per-sample trace, the window statistics, the time-ordered columns it keeps, and the
confidence a standard uncertainty stands for. :mod:`~feeder_ros.estimation.vehicle_estimator` is
the estimator that fills them.
"""

from __future__ import annotations

import enum
import math
import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from feeder_ros.estimation.stick_slip_observer import PartModel
from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = [
    "CONFIDENCE_ABSOLUTE",
    "CONFIDENCE_RELATIVE",
    "Columns",
    "EstimateTrace",
    "EstimatorConfig",
    "Status",
    "VehicleEstimate",
    "WindowStatistics",
    "confidence",
    "empty_trace",
    "input_health",
]

F64 = npt.NDArray[np.float64]
I8 = npt.NDArray[np.int8]
B = npt.NDArray[np.bool_]

#: the band a confidence is the probability of: +-(5 % of the value + 0.05 mm/s)
CONFIDENCE_RELATIVE = 0.05
CONFIDENCE_ABSOLUTE = 0.05e-3


class Status(enum.IntEnum):
    """``VehicleEstimate.status`` codes (``msg/VehicleEstimate.msg`` STATUS_*)."""

    OK = 0
    NO_INPUT = 1
    GAP = 2
    INVALID_SAMPLES = 3
    OUT_OF_ORDER = 4
    DRIVE_CHANGED = 5
    SETTLING = 6


@dataclass(frozen=True)
class EstimatorConfig:
    """Tuning of :class:`VehicleEstimator` (SI units). Defaults suit a 0.5-2 kHz accelerometer and
    drives of 5-200 Hz."""

    part: PartModel = field(default_factory=PartModel)
    window_s: float = 2.0  #: statistics window (mean speed, slip fraction)
    fit_window_s: float = 1.0  #: harmonic fit window
    min_fit_s: float = 0.3  #: data needed (after start or a drive change) before a first fit
    refit_interval_s: float = 0.1  #: refit at most this often
    order_check_interval_s: float = 2.0  #: re-select the period order this often
    max_period_order: int = 6  #: longest response period tried, in drive periods
    max_harmonic_hz: float = 450.0  #: highest harmonic fitted (also capped at 0.45*sample rate)
    displacement_max_harmonic_hz: float = 200.0  #: the same for displacement input
    coefficient_threshold_sigma: float = 3.0  #: drop harmonics below this many sigma (0: keep all)
    batch_interval_s: float = 0.01  #: stage pushes until they span this long (0: every push)
    gap_factor: float = 2.5  #: an interval > gap_factor * nominal period is a gap
    max_bridge_s: float = 0.25  #: gaps up to this long are bridged by the carrier model
    clock_reset_s: float = 1.0  #: stamps this far back reset the estimator
    frequency_band_hz: tuple[float, float] = (2.0, 300.0)  #: search band without a drive command
    frequency_tolerance: float = 0.005  #: a first command this close to the estimate is no change
    observer_settle_s: float = 0.2  #: the part's state is an initial guess for this long
    model_error_scale: float = 0.1  #: model error / (mu_s*g*kappa) at which confidence is 0.5
    #: relative standard uncertainty of the uncalibrated friction (L and D) and of the
    #: accelerometer gain (the prior of :class:`~feeder_ros.estimation.part_belief.PartBelief`)
    friction_uncertainty: float = 0.3
    gain_uncertainty: float = 0.03
    #: the part model's own error at the true parameters, relative (discretisation, model form)
    method_uncertainty: float = 0.005
    #: a mean speed is valid once this fraction of ``window_s`` lies after the carrier fit
    #: converged (and the part state settled) at the current drive setting
    min_valid_window: float = 0.5

    def __post_init__(self) -> None:
        positive = (
            "window_s",
            "fit_window_s",
            "min_fit_s",
            "refit_interval_s",
            "order_check_interval_s",
            "max_harmonic_hz",
            "displacement_max_harmonic_hz",
            "gap_factor",
            "clock_reset_s",
            "frequency_tolerance",
            "model_error_scale",
            "min_valid_window",
        )
        for name in positive:
            value = getattr(self, name)
            if not (is_number(value) and math.isfinite(value) and value > 0.0):
                raise ParameterError(f"{name}={value!r} must be finite and > 0")
        for name in (
            "max_bridge_s",
            "observer_settle_s",
            "coefficient_threshold_sigma",
            "batch_interval_s",
            "friction_uncertainty",
            "gain_uncertainty",
            "method_uncertainty",
        ):
            value = getattr(self, name)
            if not (is_number(value) and math.isfinite(value) and value >= 0.0):
                raise ParameterError(f"{name}={value!r} must be finite and >= 0")
        if not (
            isinstance(self.max_period_order, numbers.Integral)
            and not isinstance(self.max_period_order, bool)
            and self.max_period_order >= 1
        ):
            raise ParameterError(f"max_period_order={self.max_period_order!r} must be an int >= 1")
        if self.gap_factor <= 1.0:
            raise ParameterError(f"gap_factor={self.gap_factor!r} must be > 1")
        if self.min_valid_window > 1.0:
            raise ParameterError(f"min_valid_window={self.min_valid_window!r} must be <= 1")
        if self.min_fit_s > self.fit_window_s:
            raise ParameterError(
                f"min_fit_s={self.min_fit_s!r} must not exceed fit_window_s={self.fit_window_s!r}"
            )
        lo, hi = self.frequency_band_hz
        if not (0.0 < lo < hi):
            raise ParameterError(
                f"frequency_band_hz={self.frequency_band_hz!r} must be 0 < lo < hi"
            )


@dataclass(frozen=True)
class VehicleEstimate:
    """One estimate record: the fields of ``msg/VehicleEstimate.msg`` plus the time it refers to.

    Values without information are ``nan`` with confidence 0.
    """

    t_s: float
    carrier_velocity_mps: float
    part_velocity_mps: float
    part_velocity_uncertainty_mps: float  #: standard uncertainty (nan: none)
    part_velocity_confidence: float
    phase: int
    phase_confidence: float
    advance_per_cycle_m: float
    advance_per_cycle_confidence: float
    slip_fraction: float
    slip_fraction_confidence: float
    mean_speed_mps: float
    mean_speed_uncertainty_mps: float  #: standard uncertainty (nan: no valid mean speed)
    mean_speed_confidence: float
    window_s: float
    status: Status
    status_message: str
    drive_frequency_hz: float  #: commanded or estimated (nan before the first estimate)
    period_order: int  #: response period in drive periods (0 before the first fit)


@dataclass(frozen=True)
class EstimateTrace:
    """Per-sample estimates produced by the last push (samples estimated in that call, which may
    include older samples that waited for a carrier model, and bridged gap samples)."""

    t_s: F64
    carrier_v_mps: F64
    carrier_a_mps2: F64
    part_v_mps: F64
    phase: I8
    measured: B  #: False for samples synthesised to bridge a gap


def empty_trace() -> EstimateTrace:
    return EstimateTrace(
        np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, np.int8), np.zeros(0, bool)
    )


def confidence(value: float, sigma: float) -> float:
    """The probability that the truth lies within +-(5 % of |value| + 0.05 mm/s, or mm for an
    advance) of ``value`` for a normal error of standard deviation ``sigma``; 0 without a value
    or an uncertainty."""
    if not (math.isfinite(value) and math.isfinite(sigma)):
        return 0.0
    tolerance = CONFIDENCE_RELATIVE * abs(value) + CONFIDENCE_ABSOLUTE
    if sigma <= 0.0:
        return 1.0
    return math.erf(tolerance / (sigma * math.sqrt(2.0)))


@dataclass(frozen=True)
class WindowStatistics:
    """The window statistics of one record (nan / 0 where not valid)."""

    mean_speed_mps: float = math.nan
    mean_speed_uncertainty_mps: float = math.nan
    slip_fraction: float = math.nan
    slip_confidence: float = 0.0
    advance_m: float = math.nan
    advance_confidence: float = 0.0
    measured_s: float = 0.0


class Columns:
    """Time-ordered columns with amortised appends and trimming from the front."""

    def __init__(self, names: tuple[str, ...], dtypes: tuple[type, ...]) -> None:
        self._names = names
        self._data: dict[str, npt.NDArray[Any]] = {
            n: np.zeros(256, d) for n, d in zip(names, dtypes, strict=True)
        }
        self._start = 0
        self._end = 0

    def __len__(self) -> int:
        return self._end - self._start

    def col(self, name: str) -> npt.NDArray[Any]:
        return self._data[name][self._start : self._end]

    def append(self, **values: npt.NDArray[Any]) -> None:
        n = len(next(iter(values.values())))
        if n == 0:
            return
        live = self._end - self._start
        cap = self._data[self._names[0]].shape[0]
        if self._end + n > cap:
            new_cap = max(cap, 2 * (live + n))
            for name in self._names:
                arr = self._data[name]
                new = np.zeros(new_cap, arr.dtype)
                new[:live] = arr[self._start : self._end]
                self._data[name] = new
            self._start, self._end = 0, live
        for name in self._names:
            self._data[name][self._end : self._end + n] = values[name]
        self._end += n

    def drop_before(self, t_min: float, keep_one: bool = False) -> None:
        """Drop rows with ``t < t_min`` (keeping the last such row if ``keep_one``)."""
        t = self.col("t")
        k = int(np.searchsorted(t, t_min, side="left"))
        if keep_one:
            k = max(k - 1, 0)
        self._start += k

    def clear(self) -> None:
        self._start = self._end = 0


#: estimate statuses that make the estimator's diagnostics WARN (the estimate is not usable now)
WARN_STATUSES = frozenset(
    {Status.GAP, Status.INVALID_SAMPLES, Status.OUT_OF_ORDER, Status.DRIVE_CHANGED, Status.SETTLING}
)


def input_health(
    received: int,
    silent_s: float,
    waited_s: float,
    startup_timeout_s: float,
    input_timeout_s: float,
    status: Status,
    status_message: str,
) -> tuple[int, str]:
    """The estimator's health for ``/diagnostics``: (level 0 OK / 1 WARN / 2 ERROR, message).

    No sample yet: WARN while waiting, ERROR after ``startup_timeout_s``; samples that stopped
    for ``input_timeout_s``: ERROR (sensor timeout); an estimate that is not usable now (a gap,
    invalid or out-of-order samples, a drive change, settling): WARN with its message."""
    if received == 0:
        if silent_s > startup_timeout_s:
            return 2, f"no accelerometer sample in {waited_s:.1f} s since start"
        return 1, f"waiting for the first accelerometer sample ({waited_s:.1f} s since start)"
    if silent_s > input_timeout_s:
        return 2, f"sensor timeout: no accelerometer sample for {silent_s:.1f} s"
    if status in WARN_STATUSES:
        return 1, status_message or status.name
    return 0, "estimating"
