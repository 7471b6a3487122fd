"""Speed sweeps like the paper's Fig. 9: the plan, the measured points, and the result (ROS free).

A :class:`SweepPlan` is a grid of drive frequencies x amplitudes x part masses, with per point a
settle time (the drive at the point's setting, nothing measured) and then either a measurement
window (``window_s``) or a distance (``distance_m``, the paper's 8.5 cm: the mean speed over the
time a part takes to travel it). Plans come from a YAML mapping (``config/identify.yaml``) and/or
command-line ranges such as ``38:58:0.5`` (start:stop:step, stop included); every refusal names the
field and the value.

A :class:`SweepPoint` is one measured point (frequency, amplitude in % and N, part mass, mean part
speed, measurement duration, ok or the reason it is not); a :class:`SweepResult` holds the points
of one sweep, writes and reads them as CSV, and groups them per (amplitude, part mass) into the
arrays a frequency-response fit takes (:meth:`SweepResult.groups`).

Units are SI throughout (speeds in m/s, masses in kg); amplitudes are percent of the drive's full
scale, ``amplitude_n = amplitude_percent / 100 * full_scale_force_n`` (as the drive interface maps
them).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import numpy.typing as npt

from feeder_ros.csv_cells import csv_cell
from feeder_ros.identification.rational_fit import FREQUENCY_RESOLUTION_HZ, distinct_frequencies
from feeder_ros.physics.parameters import is_number

__all__ = [
    "CSV_COLUMNS",
    "SweepDataError",
    "SweepGroup",
    "SweepPlan",
    "SweepPlanError",
    "SweepPoint",
    "SweepResult",
    "check_fit_data",
    "parse_orders",
    "parse_values",
]

F64 = npt.NDArray[np.float64]

#: values a range may expand to (a typo such as 38:58:0.0005 is refused, not run)
MAX_VALUES = 10_000


class SweepPlanError(ValueError):
    """A sweep plan that cannot be run; the message names the field and the value."""

    def __init__(self, name: str, value: object, reason: str) -> None:
        self.name = name
        self.value = value
        self.reason = reason
        super().__init__(f"{name}={value!r}: {reason}")


class SweepDataError(ValueError):
    """Sweep data that cannot be used (unreadable CSV, NaN, too few points, one frequency)."""


# ------------------------------------------------------------------------------------ parsing


def _number(name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SweepPlanError(name, text, "not a number") from None
    if not math.isfinite(value):
        raise SweepPlanError(name, text, "not finite")
    return value


def _expand_range(name: str, item: str) -> list[float]:
    parts = [p.strip() for p in item.split(":")]
    if len(parts) != 3:
        raise SweepPlanError(name, item, "a range is start:stop:step, e.g. 38:58:0.5")
    start, stop, step = (_number(name, p) for p in parts)
    if step <= 0.0:
        raise SweepPlanError(name, item, "the step must be > 0")
    if stop < start:
        raise SweepPlanError(name, item, "stop is below start")
    intervals = (stop - start) / step
    count = math.floor(intervals + 1e-9) + 1
    if count > MAX_VALUES:
        raise SweepPlanError(name, item, f"{count} values; at most {MAX_VALUES}")
    # k*step from start, rounded to 12 significant digits: 38 + 3*0.1 is 38.3, not 38.300000001
    return [float(f"{start + k * step:.12g}") for k in range(count)]


def parse_values(name: str, spec: object) -> tuple[float, ...]:
    """Values from a number, a list of numbers, or a string of comma-separated numbers and
    ``start:stop:step`` ranges (stop included when it lies on the grid)."""
    items: list[object]
    if isinstance(spec, bool | np.bool_):
        raise SweepPlanError(name, spec, "not a number")
    if is_number(spec):
        items = [spec]
    elif isinstance(spec, str):
        items = [p.strip() for p in spec.split(",")]
        if not any(items):
            raise SweepPlanError(name, spec, "no values")
    elif isinstance(spec, Sequence):
        items = list(spec)
    else:
        raise SweepPlanError(name, spec, "expected a number, a list or a range like 38:58:0.5")
    values: list[float] = []
    for item in items:
        if isinstance(item, bool | np.bool_):
            raise SweepPlanError(name, item, "not a number")
        if is_number(item):
            if not math.isfinite(float(item)):
                raise SweepPlanError(name, item, "not finite")
            values.append(float(item))
        elif isinstance(item, str) and ":" in item:
            values.extend(_expand_range(name, item))
        elif isinstance(item, str) and item:
            values.append(_number(name, item))
        else:
            raise SweepPlanError(name, item, "not a number or a start:stop:step range")
    if not values:
        raise SweepPlanError(name, spec, "no values")
    if len(values) > MAX_VALUES:
        raise SweepPlanError(name, spec, f"{len(values)} values; at most {MAX_VALUES}")
    return tuple(values)


def parse_orders(spec: object) -> tuple[tuple[int, int], ...]:
    """Model orders ``zeros/poles`` from ``"1/2, 1/3"`` or a list of such strings or pairs.

    A model needs at least one pole and no more zeros than poles (a proper G(s))."""
    items: list[object]
    if isinstance(spec, str):
        items = [p.strip() for p in spec.split(",") if p.strip()]
    elif isinstance(spec, Sequence):
        items = list(spec)
    else:
        raise SweepPlanError("orders", spec, "expected zeros/poles pairs such as '1/2, 1/3'")
    if not items:
        raise SweepPlanError("orders", spec, "no orders")
    orders: list[tuple[int, int]] = []
    for item in items:
        if isinstance(item, str):
            zeros_text, sep, poles_text = item.partition("/")
            try:
                pair = (int(zeros_text), int(poles_text))
            except ValueError:
                pair = (-1, -1)
            if not sep or pair == (-1, -1):
                raise SweepPlanError("orders", item, "expected zeros/poles, e.g. 1/2")
        elif (
            isinstance(item, Sequence)
            and len(item) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in item)
        ):
            pair = (int(item[0]), int(item[1]))
        else:
            raise SweepPlanError("orders", item, "expected zeros/poles, e.g. 1/2")
        zeros, poles = pair
        if poles < 1 or zeros < 0:
            raise SweepPlanError("orders", item, "needs >= 1 pole and >= 0 zeros")
        if zeros > poles:
            raise SweepPlanError("orders", item, "more zeros than poles (G(s) must be proper)")
        if poles > 8:
            raise SweepPlanError("orders", item, "more than 8 poles")
        if pair not in orders:
            orders.append(pair)
    return tuple(orders)


# --------------------------------------------------------------------------------------- plan


def _positive(name: str, value: object, *, allow_zero: bool = False) -> float:
    if not is_number(value):
        raise SweepPlanError(name, value, "not a number")
    number = float(value)
    if not math.isfinite(number):
        raise SweepPlanError(name, value, "not finite")
    if number < 0.0 or (number == 0.0 and not allow_zero):
        raise SweepPlanError(name, value, ">= 0 required" if allow_zero else "> 0 required")
    return number


@dataclass(frozen=True)
class SweepPlan:
    """What to measure. Exactly one of ``window_s`` and ``distance_m`` is set.

    * ``settle_s``: time at the point's drive setting before measuring (the start-up transient of
      the carrier and parts is left out);
    * ``window_s``: mean part speed over this time; ``distance_m``: mean speed over the time a
      part takes to travel this distance (the paper's 8.5 cm), at most ``max_window_s``;
    * ``ramp_time_s``: the live source's ramp from one setting to the next (the drive interface's
      rate limits may lengthen it);
    * ``full_scale_force_n``: force at 100 % amplitude (the drive interface's parameter).
    """

    frequencies_hz: tuple[float, ...]
    amplitudes_percent: tuple[float, ...]
    part_masses_kg: tuple[float, ...]
    settle_s: float = 1.0
    window_s: float | None = 3.0
    distance_m: float | None = None
    max_window_s: float = 60.0
    ramp_time_s: float = 0.5
    full_scale_force_n: float = 100.0

    def __post_init__(self) -> None:
        def checked(
            name: str, values: Iterable[float], low: float, high: float, frequencies: bool = False
        ) -> tuple[float, ...]:
            out: list[float] = []
            for value in values:
                if not is_number(value):
                    raise SweepPlanError(name, value, "not a number")
                number = float(value)
                if not (math.isfinite(number) and low < number <= high):
                    raise SweepPlanError(name, value, f"must lie in ({low:g}, {high:g}]")
                out.append(number)
            if not out:
                raise SweepPlanError(name, (), "no values")
            ordered = sorted(set(out))
            if len(ordered) != len(out):
                raise SweepPlanError(name, tuple(out), "a value appears twice")
            if frequencies and distinct_frequencies(ordered)[0].size != len(out):
                # the fit takes such frequencies as one (rational_fit.FREQUENCY_RESOLUTION_HZ)
                raise SweepPlanError(
                    name,
                    tuple(out),
                    f"two frequencies within {FREQUENCY_RESOLUTION_HZ:g} Hz are one frequency",
                )
            return tuple(ordered)

        object.__setattr__(
            self,
            "frequencies_hz",
            checked("frequencies_hz", self.frequencies_hz, 0.0, 1e4, frequencies=True),
        )
        object.__setattr__(
            self,
            "amplitudes_percent",
            checked("amplitudes_percent", self.amplitudes_percent, 0.0, 100.0),
        )
        object.__setattr__(
            self, "part_masses_kg", checked("part_masses_kg", self.part_masses_kg, 0.0, 1e3)
        )
        object.__setattr__(self, "settle_s", _positive("settle_s", self.settle_s, allow_zero=True))
        object.__setattr__(self, "max_window_s", _positive("max_window_s", self.max_window_s))
        object.__setattr__(
            self, "ramp_time_s", _positive("ramp_time_s", self.ramp_time_s, allow_zero=True)
        )
        object.__setattr__(
            self, "full_scale_force_n", _positive("full_scale_force_n", self.full_scale_force_n)
        )
        if (self.window_s is None) == (self.distance_m is None):
            raise SweepPlanError(
                "window_s/distance_m",
                (self.window_s, self.distance_m),
                "give exactly one: a measurement window or a distance",
            )
        if self.window_s is not None:
            window = _positive("window_s", self.window_s)
            if window > self.max_window_s:
                raise SweepPlanError("window_s", self.window_s, "exceeds max_window_s")
            object.__setattr__(self, "window_s", window)
        if self.distance_m is not None:
            object.__setattr__(self, "distance_m", _positive("distance_m", self.distance_m))
        count = len(self.frequencies_hz) * len(self.amplitudes_percent) * len(self.part_masses_kg)
        if count > MAX_VALUES:
            raise SweepPlanError("points", count, f"at most {MAX_VALUES} points per sweep")

    # -- construction ----------------------------------------------------------------------------
    KEYS = (
        "frequencies_hz",
        "amplitudes_percent",
        "part_masses_kg",
        "settle_s",
        "window_s",
        "distance_m",
        "max_window_s",
        "ramp_time_s",
        "full_scale_force_n",
    )

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], base: SweepPlan | None = None) -> SweepPlan:
        """A plan from a YAML mapping (the ``sweep:`` section of ``config/identify.yaml``);
        missing keys come from ``base`` (or the defaults). Unknown keys are refused by name.

        ``frequencies_hz``, ``amplitudes_percent`` and ``part_masses_kg`` take a number, a list or
        a string of numbers and ranges (``"38:58:0.5, 60"``). Giving ``window_s`` drops the
        base's ``distance_m`` and vice versa."""
        if not isinstance(values, Mapping):
            raise SweepPlanError("sweep", values, "expected a mapping of plan fields")
        unknown = sorted(str(k) for k in values if k not in cls.KEYS)
        if unknown:
            raise SweepPlanError(
                unknown[0], values[unknown[0]], f"unknown field (known: {', '.join(cls.KEYS)})"
            )
        changes: dict[str, Any] = {}
        for name in ("frequencies_hz", "amplitudes_percent", "part_masses_kg"):
            if name in values:
                changes[name] = parse_values(name, values[name])
        for name in ("settle_s", "max_window_s", "ramp_time_s", "full_scale_force_n"):
            if name in values:
                changes[name] = values[name]
        if "window_s" in values and values["window_s"] is not None:
            changes["window_s"] = values["window_s"]
            if "distance_m" not in values or values["distance_m"] is None:
                changes["distance_m"] = None
        if "distance_m" in values and values["distance_m"] is not None:
            changes["distance_m"] = values["distance_m"]
            if "window_s" not in values or values["window_s"] is None:
                changes["window_s"] = None
        if base is not None:
            return replace(base, **changes)
        missing = [
            n
            for n in ("frequencies_hz", "amplitudes_percent", "part_masses_kg")
            if n not in changes
        ]
        if missing:
            raise SweepPlanError(missing[0], None, "required")
        return cls(**changes)

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    # -- the grid --------------------------------------------------------------------------------
    def amplitude_n(self, amplitude_percent: float) -> float:
        return amplitude_percent / 100.0 * self.full_scale_force_n

    @property
    def point_count(self) -> int:
        return len(self.frequencies_hz) * len(self.amplitudes_percent) * len(self.part_masses_kg)

    def settings(self) -> Iterator[tuple[float, float, float]]:
        """(part mass kg, amplitude %, frequency Hz) in measuring order: per mass, per amplitude,
        frequencies upward (a live sweep then ramps by one frequency step at a time)."""
        for mass in self.part_masses_kg:
            for amplitude in self.amplitudes_percent:
                for frequency in self.frequencies_hz:
                    yield mass, amplitude, frequency

    def describe(self) -> str:
        f = self.frequencies_hz
        freq = f"{f[0]:g}-{f[-1]:g} Hz ({len(f)} frequencies)" if len(f) > 1 else f"{f[0]:g} Hz"
        measure = (
            f"window {self.window_s:g} s"
            if self.window_s is not None
            else f"distance {self.distance_m:g} m (at most {self.max_window_s:g} s)"
        )
        return (
            f"{freq} x amplitudes {', '.join(f'{a:g}' for a in self.amplitudes_percent)} % "
            f"(full scale {self.full_scale_force_n:g} N) x part masses "
            f"{', '.join(f'{m * 1e3:g}' for m in self.part_masses_kg)} g = {self.point_count} "
            f"points; settle {self.settle_s:g} s, {measure}"
        )


# ------------------------------------------------------------------------------------- points


@dataclass(frozen=True)
class SweepPoint:
    """One measured point. ``speed_mps``: mean part speed over ``duration_s`` (NaN when not
    measured); ``ok`` false with a ``reason`` when the point cannot be used."""

    frequency_hz: float
    amplitude_percent: float
    amplitude_n: float
    part_mass_kg: float
    speed_mps: float
    duration_s: float
    slip_fraction: float = math.nan
    ok: bool = True
    reason: str = ""


CSV_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(SweepPoint))


@dataclass(frozen=True)
class SweepGroup:
    """The usable points of one (amplitude, part mass) curve, sorted by frequency; ``excluded``
    counts the points left out, per reason."""

    amplitude_percent: float
    amplitude_n: float
    part_mass_kg: float
    frequency_hz: F64
    speed_mps: F64
    excluded: dict[str, int] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return f"{self.amplitude_percent:g} % / {self.part_mass_kg * 1e3:g} g"


@dataclass(frozen=True)
class SweepResult:
    """The points of one sweep and where they came from (``source``: sim, live, bag, csv)."""

    points: tuple[SweepPoint, ...]
    source: str = ""
    full_scale_force_n: float = math.nan

    def __len__(self) -> int:
        return len(self.points)

    @property
    def ok_count(self) -> int:
        return sum(p.ok for p in self.points)

    # -- CSV -------------------------------------------------------------------------------------
    def write_csv(self, stream: TextIO) -> None:
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(CSV_COLUMNS)
        for point in self.points:
            writer.writerow([csv_cell(getattr(point, name)) for name in CSV_COLUMNS])

    @classmethod
    def read_csv(cls, path: str | Path, source: str | None = None) -> SweepResult:
        """Points from a CSV written by :meth:`write_csv`. Refused with the row and column named:
        a missing column, a value that is not a number, a usable (ok) row whose frequency,
        amplitude, mass or speed is NaN/inf, an amplitude in % and N that disagree with the other
        rows' full scale."""
        path = Path(path)
        try:
            with path.open(newline="", encoding="utf-8") as stream:
                rows = list(csv.reader(stream))
        except (OSError, UnicodeDecodeError, csv.Error) as error:
            raise SweepDataError(f"{path}: cannot read: {error}") from None
        if not rows:
            raise SweepDataError(f"{path}: empty file (expected a header {','.join(CSV_COLUMNS)})")
        header = [h.strip() for h in rows[0]]
        missing = [c for c in CSV_COLUMNS if c not in header and c not in ("slip_fraction",)]
        if missing:
            raise SweepDataError(f"{path}: missing column(s) {', '.join(missing)}")
        index = {name: header.index(name) for name in CSV_COLUMNS if name in header}
        points: list[SweepPoint] = []
        for line, row in enumerate(rows[1:], start=2):
            if not row or all(not cell.strip() for cell in row):
                continue

            def cell(name: str, row: list[str] = row, line: int = line) -> str:
                k = index.get(name)
                if k is None:
                    return "nan"
                if k >= len(row):
                    raise SweepDataError(f"{path}: line {line}: no value for {name}")
                return row[k].strip()

            values: dict[str, Any] = {}
            for name in (
                "frequency_hz",
                "amplitude_percent",
                "amplitude_n",
                "part_mass_kg",
                "speed_mps",
                "duration_s",
                "slip_fraction",
            ):
                text = cell(name)
                try:
                    values[name] = float(text)
                except ValueError:
                    raise SweepDataError(
                        f"{path}: line {line}: {name}={text!r} is not a number"
                    ) from None
            ok_text = cell("ok").lower()
            if ok_text not in ("0", "1", "true", "false"):
                raise SweepDataError(f"{path}: line {line}: ok={ok_text!r} is not 0/1")
            ok = ok_text in ("1", "true")
            reason = cell("reason") if "reason" in index and index["reason"] < len(row) else ""
            if ok:
                for name in ("frequency_hz", "amplitude_percent", "amplitude_n", "part_mass_kg"):
                    if not math.isfinite(values[name]):
                        raise SweepDataError(
                            f"{path}: line {line}: {name}={values[name]} in a usable row (ok=1)"
                        )
                if not math.isfinite(values["speed_mps"]):
                    raise SweepDataError(
                        f"{path}: line {line}: speed_mps={values['speed_mps']} in a usable row "
                        "(ok=1); mark the point ok=0 with a reason, or measure it again"
                    )
            points.append(SweepPoint(**values, ok=ok, reason=reason))
        if not points:
            raise SweepDataError(f"{path}: no points (only a header)")
        full_scale = _full_scale(points, str(path))
        return cls(tuple(points), source or f"csv {path}", full_scale)

    # -- grouping --------------------------------------------------------------------------------
    def groups(self, min_speed_mps: float = 0.0) -> list[SweepGroup]:
        """The usable points per (amplitude %, part mass), each sorted by frequency.

        Left out (and counted in ``excluded``): points not ok, and points whose speed is not above
        ``min_speed_mps`` (a magnitude |G(j w)| * A cannot be negative or zero; the paper, too,
        kept only points where the part moved). Points repeated at one frequency are averaged."""
        keys: dict[tuple[float, float], list[SweepPoint]] = {}
        for point in self.points:
            keys.setdefault((point.amplitude_percent, point.part_mass_kg), []).append(point)
        out: list[SweepGroup] = []
        for (amplitude, mass), members in sorted(keys.items()):
            excluded: dict[str, int] = {}
            by_frequency: dict[float, list[float]] = {}
            amplitude_n = members[0].amplitude_n
            for point in members:
                if not point.ok:
                    reason = point.reason or "not ok"
                    excluded[reason] = excluded.get(reason, 0) + 1
                elif not point.speed_mps > min_speed_mps:
                    reason = f"speed not above {min_speed_mps:g} m/s (part not moving forward)"
                    excluded[reason] = excluded.get(reason, 0) + 1
                else:
                    by_frequency.setdefault(point.frequency_hz, []).append(point.speed_mps)
            frequencies = np.array(sorted(by_frequency), dtype=np.float64)
            speeds = np.array([np.mean(by_frequency[f]) for f in sorted(by_frequency)])
            out.append(
                SweepGroup(
                    amplitude_percent=amplitude,
                    amplitude_n=amplitude_n,
                    part_mass_kg=mass,
                    frequency_hz=frequencies,
                    speed_mps=speeds.astype(np.float64),
                    excluded=excluded,
                )
            )
        return out


def _full_scale(points: Sequence[SweepPoint], where: str) -> float:
    ratios = [
        p.amplitude_n / p.amplitude_percent * 100.0
        for p in points
        if p.amplitude_percent > 0 and math.isfinite(p.amplitude_n) and p.amplitude_n > 0
    ]
    if not ratios:
        return math.nan
    full = float(np.median(ratios))
    bad = [r for r in ratios if not math.isclose(r, full, rel_tol=1e-6)]
    if bad:
        raise SweepDataError(
            f"{where}: amplitude_n/amplitude_percent gives full scales {full:g} N and "
            f"{bad[0]:g} N; one sweep has one drive full scale"
        )
    return full


def check_fit_data(
    frequency_hz: npt.ArrayLike,
    speed_mps: npt.ArrayLike,
    min_points: int,
    what: str = "sweep",
) -> None:
    """Refuse data no frequency-response fit can use, with the reason: non-finite values, fewer
    than ``min_points`` points, a single frequency."""
    f = np.asarray(frequency_hz, dtype=np.float64)
    v = np.asarray(speed_mps, dtype=np.float64)
    if f.shape != v.shape or f.ndim != 1:
        raise SweepDataError(f"{what}: {f.shape} frequencies but {v.shape} speeds")
    bad = np.flatnonzero(~np.isfinite(f) | ~np.isfinite(v))
    if bad.size:
        k = int(bad[0])
        raise SweepDataError(
            f"{what}: {bad.size} non-finite value(s), first at {f[k]:g} Hz (speed {v[k]:g} m/s)"
        )
    if f.size == 0:
        raise SweepDataError(f"{what}: no usable points")
    distinct, _ = distinct_frequencies(f)
    if distinct.size == 1:
        raise SweepDataError(
            f"{what}: a single frequency ({f[0]:g} Hz, {f.size} point(s)); a frequency response "
            "needs points at several frequencies"
        )
    if f.size < min_points:
        raise SweepDataError(
            f"{what}: only {f.size} usable point(s); the models asked for need at least "
            f"{min_points} (more points than parameters, and some held out)"
        )
