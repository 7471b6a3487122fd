"""What the drive may be asked to do: frequency range, amplitude range, forbidden bands, ramp rates,
and the drive's amplitude-% to force mapping; clamping of requested set points into them."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum

__all__ = [
    "DriveLimits",
    "LimitError",
    "Outcome",
    "SetPoint",
    "clamp_set_point",
    "parse_bands",
    "set_point_refusal",
]


class LimitError(ValueError):
    """Limits that contradict each other (e.g. a forbidden band covering the whole range)."""


class Outcome(IntEnum):
    """Result codes shared with SetDrive/SetTargetSpeed (ACCEPTED, CLAMPED, REFUSED)."""

    ACCEPTED = 0
    CLAMPED = 1
    REFUSED = 2


@dataclass(frozen=True)
class DriveLimits:
    """Validated drive limits; defaults: 5-300 Hz, 0-100 %, 50 Hz/s, 50 %/s, 100 N full scale."""

    min_frequency_hz: float = 5.0
    max_frequency_hz: float = 300.0
    max_amplitude_percent: float = 100.0
    max_frequency_rate_hz_per_s: float = 50.0
    max_amplitude_rate_percent_per_s: float = 50.0
    forbidden_bands_hz: tuple[tuple[float, float], ...] = field(default_factory=tuple)
    full_scale_force_n: float = 100.0

    def __post_init__(self) -> None:
        numbers = {
            "min_frequency_hz": self.min_frequency_hz,
            "max_frequency_hz": self.max_frequency_hz,
            "max_amplitude_percent": self.max_amplitude_percent,
            "max_frequency_rate_hz_per_s": self.max_frequency_rate_hz_per_s,
            "max_amplitude_rate_percent_per_s": self.max_amplitude_rate_percent_per_s,
            "full_scale_force_n": self.full_scale_force_n,
        }
        for name, value in numbers.items():
            if not math.isfinite(value) or value <= 0.0:
                raise LimitError(f"{name}={value!r} must be a finite value > 0")
        if self.min_frequency_hz >= self.max_frequency_hz:
            raise LimitError(
                f"min_frequency_hz={self.min_frequency_hz:g} must be below "
                f"max_frequency_hz={self.max_frequency_hz:g}"
            )
        if self.max_amplitude_percent > 100.0:
            raise LimitError(f"max_amplitude_percent={self.max_amplitude_percent:g} exceeds 100 %")
        bands = tuple(sorted((float(lo), float(hi)) for lo, hi in self.forbidden_bands_hz))
        for low, high in bands:
            if not (math.isfinite(low) and math.isfinite(high)) or low >= high:
                raise LimitError(f"forbidden band [{low:g}, {high:g}] Hz: needs low < high")
        object.__setattr__(self, "forbidden_bands_hz", bands)
        if not self.allowed_intervals():
            raise LimitError(
                f"the forbidden bands cover all of {self.min_frequency_hz:g}-"
                f"{self.max_frequency_hz:g} Hz: no frequency is allowed"
            )

    def force_n(self, amplitude_percent: float) -> float:
        """The drive's linear mapping: force = amplitude_percent / 100 * full_scale_force_n."""
        return amplitude_percent / 100.0 * self.full_scale_force_n

    def forbidden_band_of(self, frequency_hz: float) -> tuple[float, float] | None:
        """The forbidden band strictly containing ``frequency_hz`` (its edges are allowed)."""
        for low, high in self.forbidden_bands_hz:
            if low < frequency_hz < high:
                return (low, high)
        return None

    def allowed_intervals(self) -> list[tuple[float, float]]:
        """The closed frequency intervals a set point may lie in, in ascending order."""
        intervals = [(self.min_frequency_hz, self.max_frequency_hz)]
        for low, high in self.forbidden_bands_hz:  # open bands: their edges stay allowed
            cut: list[tuple[float, float]] = []
            for a, b in intervals:
                if high <= a or low >= b:
                    cut.append((a, b))
                    continue
                if a <= low:
                    cut.append((a, low))
                if high <= b:
                    cut.append((high, b))
            intervals = cut
        return intervals

    def nearest_allowed_frequency(self, frequency_hz: float) -> float:
        """The allowed frequency closest to ``frequency_hz`` (ties: the lower one)."""
        best = math.inf
        choice = self.min_frequency_hz
        for a, b in self.allowed_intervals():
            candidate = min(max(frequency_hz, a), b)
            distance = abs(candidate - frequency_hz)
            if distance < best:
                best, choice = distance, candidate
        return choice

    def minimum_ramp_time_s(
        self, from_hz: float, from_percent: float, to_hz: float, to_percent: float
    ) -> float:
        """Shortest ramp the rate limits allow (frequency changes at zero amplitude are free)."""
        frequency_time = 0.0
        if from_percent > 0.0 or to_percent > 0.0:
            frequency_time = abs(to_hz - from_hz) / self.max_frequency_rate_hz_per_s
        amplitude_time = abs(to_percent - from_percent) / self.max_amplitude_rate_percent_per_s
        return max(frequency_time, amplitude_time)


@dataclass(frozen=True)
class SetPoint:
    """A set point after clamping: what will be driven, and why it differs from the request."""

    outcome: Outcome
    reason: str
    frequency_hz: float = 0.0
    amplitude_percent: float = 0.0
    ramp_time_s: float = 0.0


def set_point_refusal(
    limits: DriveLimits, frequency_hz: float, amplitude_percent: float, ramp_time_s: float
) -> str:
    """Why a requested set point is impossible, naming each impossible value; "" when it is not.

    Impossible: a value that is not finite, a frequency <= 0 Hz, an amplitude < 0 % or a ramp
    time < 0 s. No drive can do what such a request says, so moving it into the limits would
    answer a different question: it is refused. Only a possible value outside the configured
    limits (e.g. 1 Hz or 400 Hz against 5-300 Hz, 120 %) is clamped, by :func:`clamp_set_point`.
    """
    frequencies = f"{limits.min_frequency_hz:g}-{limits.max_frequency_hz:g} Hz"
    amplitudes = f"0-{limits.max_amplitude_percent:g} %"
    problems: list[str] = []
    for name, value, relation, unit, in_limits in (
        ("frequency_hz", frequency_hz, ">", "Hz", f" (this drive: {frequencies})"),
        ("amplitude_percent", amplitude_percent, ">=", "%", f" (this drive: {amplitudes})"),
        ("ramp_time_s", ramp_time_s, ">=", "s", ""),
    ):
        if not math.isfinite(value):
            problems.append(f"{name}={value!r} is not finite")
        elif value < 0.0 or (relation == ">" and value == 0.0):
            problems.append(f"{name}={value:g} must be {relation} 0 {unit}{in_limits}")
    return "; ".join(problems)


def clamp_set_point(
    limits: DriveLimits, frequency_hz: float, amplitude_percent: float, ramp_time_s: float
) -> SetPoint:
    """Move a requested set point into the limits (CLAMPED, with the reason) or refuse it.

    Impossible values (see :func:`set_point_refusal`) are REFUSED with the reason naming them:
    they are malformed, not out of range. The ramp time here is the requested one; the ramp
    generator lengthens it to the rate limits.
    """
    refusal = set_point_refusal(limits, frequency_hz, amplitude_percent, ramp_time_s)
    if refusal:
        return SetPoint(Outcome.REFUSED, refusal)
    notes: list[str] = []
    frequency = frequency_hz
    if not limits.min_frequency_hz <= frequency <= limits.max_frequency_hz:
        frequency = min(max(frequency, limits.min_frequency_hz), limits.max_frequency_hz)
        notes.append(
            f"frequency {frequency_hz:g} Hz outside {limits.min_frequency_hz:g}-"
            f"{limits.max_frequency_hz:g} Hz, clamped to {frequency:g} Hz"
        )
    band = limits.forbidden_band_of(frequency)
    if band is not None:
        moved = limits.nearest_allowed_frequency(frequency)
        notes.append(
            f"frequency {frequency:g} Hz in forbidden band {band[0]:g}-{band[1]:g} Hz, "
            f"moved to {moved:g} Hz"
        )
        frequency = moved
    amplitude = amplitude_percent
    if amplitude > limits.max_amplitude_percent:
        amplitude = limits.max_amplitude_percent
        notes.append(
            f"amplitude {amplitude_percent:g} % outside 0-{limits.max_amplitude_percent:g} %, "
            f"clamped to {amplitude:g} %"
        )
    outcome = Outcome.CLAMPED if notes else Outcome.ACCEPTED
    return SetPoint(outcome, "; ".join(notes), frequency, amplitude, ramp_time_s)


def parse_bands(values: Sequence[float] | str) -> tuple[tuple[float, float], ...]:
    """Forbidden bands from a flat list ``[low1, high1, low2, high2, ...]`` or the same as text
    ("45, 55, 120, 130"); an empty list or text means none."""
    if isinstance(values, str):
        items = [item.strip() for item in values.replace(";", ",").split(",")]
        numbers: list[float] = []
        for item in items:
            if not item:
                continue
            try:
                numbers.append(float(item))
            except ValueError:
                raise LimitError(f"forbidden band value {item!r} is not a number") from None
    else:
        numbers = [float(value) for value in values]
    if len(numbers) % 2:
        raise LimitError(
            f"forbidden bands need [low, high] pairs; got {len(numbers)} values: {numbers}"
        )
    bands = tuple((numbers[i], numbers[i + 1]) for i in range(0, len(numbers), 2))
    for low, high in bands:
        if not (math.isfinite(low) and math.isfinite(high)) or low >= high:
            raise LimitError(f"forbidden band [{low:g}, {high:g}] Hz: needs low < high")
    return bands
