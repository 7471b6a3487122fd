"""Speed models: which drive setting gives a requested mean part speed; which speeds are reachable.

:class:`SpeedModel` is the interface the drive interface uses; :class:`TableSpeedModel` is the one
built from the physics core (:func:`compute_speed_table`, a grid of exact simulations over the
allowed frequencies and amplitudes, cached on disk by :func:`cached_speed_table`). An identified
model (e.g. a transfer-function fit loaded from YAML) only has to implement the protocol.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import numpy.typing as npt

from feeder_ros.atomic_files import atomic_path
from feeder_ros.drive.limits import DriveLimits
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import PartSpec, simulate_many

__all__ = [
    "STEERABLE",
    "SpeedChoice",
    "SpeedModel",
    "TableSpeedModel",
    "cached_speed_table",
    "compute_speed_table",
    "default_cache_dir",
    "steerable",
]

F64 = npt.NDArray[np.float64]
TABLE_VERSION = 1  # bump when the table's meaning changes: old cache files are then ignored
#: sensitivities d ln v / d ln A at which the amplitude steers the speed (choice of a set point)
STEERABLE = (0.5, 2.0)


def steerable(sensitivity: float) -> bool:
    """Whether the amplitude steers the speed at this ``d ln v / d ln A`` (NaN: no)."""
    low, high = STEERABLE
    return bool(low <= sensitivity <= high)


@dataclass(frozen=True)
class SpeedChoice:
    frequency_hz: float
    amplitude_percent: float
    predicted_speed_mps: float


class SpeedModel(Protocol):
    """What target-speed mode needs from a model of the feeder."""

    def reachable_range(self) -> tuple[float, float]:
        """(slowest, fastest) mean part speed the model can produce within the limits [m/s]."""
        ...

    def choose(self, speed_mps: float) -> SpeedChoice | None:
        """A setting that gives ``speed_mps``, or None if the speed is not reachable."""
        ...

    def nearest(self, speed_mps: float) -> SpeedChoice:
        """The setting for the reachable speed closest to ``speed_mps``."""
        ...


class TableSpeedModel:
    """Mean part speed tabulated over frequencies x amplitudes; linear along amplitude.

    For a requested speed each frequency row is searched for amplitude intervals whose end speeds
    bracket it. Steerable brackets come first: those where the speed's sensitivity to the
    amplitude, ``d ln v / d ln A``, lies within :data:`STEERABLE`. Where it is far below 1 (a
    plateau, where the slip pattern changes) the amplitude hardly moves the speed and the
    friction, the part model's least known input, sets it: there the estimate is least sure and
    the speed trim cannot correct a model error (the demo's 8 mm/s at 22 Hz / 25 %: +-6 mm/s,
    and a trim that had not landed in 75 s). Far above 1 is the steep slip threshold. Among
    them, the bracket whose end speeds differ least wins: linear interpolation inside a bracket
    can be off by at most that difference, so this is the setting the table predicts best.
    Ties: the lower amplitude, then the lower frequency. No steerable bracket: the best of the
    others. Frequencies must be allowed set points.
    """

    def __init__(
        self,
        frequencies_hz: npt.ArrayLike,
        amplitudes_percent: npt.ArrayLike,
        speeds_mps: npt.ArrayLike,
    ) -> None:
        self.frequencies_hz = np.asarray(frequencies_hz, dtype=np.float64)
        self.amplitudes_percent = np.asarray(amplitudes_percent, dtype=np.float64)
        self.speeds_mps = np.asarray(speeds_mps, dtype=np.float64)
        shape = (self.frequencies_hz.size, self.amplitudes_percent.size)
        if self.speeds_mps.shape != shape:
            raise ValueError(f"speed table shape {self.speeds_mps.shape} != grid {shape}")
        if self.amplitudes_percent.size < 2 or np.any(np.diff(self.amplitudes_percent) <= 0.0):
            raise ValueError("amplitudes_percent must be >= 2 increasing values")
        if self.frequencies_hz.size < 1 or not np.all(np.isfinite(self.speeds_mps)):
            raise ValueError("speed table needs >= 1 frequency and finite speeds")

    def reachable_range(self) -> tuple[float, float]:
        return float(self.speeds_mps.min()), float(self.speeds_mps.max())

    def predict(self, frequency_hz: float, amplitude_percent: float) -> float:
        """Speed at a tabulated frequency (the nearest row), interpolated along amplitude."""
        row = int(np.argmin(np.abs(self.frequencies_hz - frequency_hz)))
        return float(np.interp(amplitude_percent, self.amplitudes_percent, self.speeds_mps[row]))

    def amplitude_sensitivity(self, frequency_hz: float, amplitude_percent: float) -> float:
        """The relative change of the predicted speed per relative change of the amplitude,
        ``d ln v / d ln A``, at a tabulated frequency (the nearest row): the slope of the
        amplitude interval holding ``amplitude_percent`` (the table is linear inside it); on an
        inner grid point, of the two intervals around it. NaN where the speed or the slope is
        not positive (a falling speed: the table cannot say which way to step)."""
        row = int(np.argmin(np.abs(self.frequencies_hz - frequency_hz)))
        a, v = self.amplitudes_percent, self.speeds_mps[row]
        j = int(np.clip(np.searchsorted(a, amplitude_percent) - 1, 0, a.size - 2))
        lower, upper = j, j + 1
        on_grid = np.isclose(a, amplitude_percent, rtol=0.0, atol=1e-9)
        if on_grid.any():
            k = int(np.argmax(on_grid))
            lower, upper = max(k - 1, 0), min(k + 1, a.size - 1)
        speed = float(np.interp(amplitude_percent, a, v))
        slope = float((v[upper] - v[lower]) / (a[upper] - a[lower]))
        value = slope * amplitude_percent / speed if speed > 0.0 else math.nan
        return value if math.isfinite(value) and value > 0.0 else math.nan

    def choose(self, speed_mps: float, frequency_hz: float | None = None) -> SpeedChoice | None:
        """See the class docstring; with ``frequency_hz``, at that tabulated frequency only (the
        nearest row)."""
        if not math.isfinite(speed_mps):
            return None
        best: SpeedChoice | None = None
        best_key = (math.inf, math.inf, math.inf)
        a = self.amplitudes_percent
        rows = range(self.frequencies_hz.size)
        if frequency_hz is not None:
            nearest = int(np.argmin(np.abs(self.frequencies_hz - frequency_hz)))
            rows = range(nearest, nearest + 1)
        for row in rows:
            frequency, v = self.frequencies_hz[row], self.speeds_mps[row]
            for j in range(a.size - 1):
                v0, v1 = v[j], v[j + 1]
                if not min(v0, v1) <= speed_mps <= max(v0, v1):
                    continue
                fraction = 0.0 if v1 == v0 else (speed_mps - v0) / (v1 - v0)
                amplitude = float(a[j] + fraction * (a[j + 1] - a[j]))
                slope = (v1 - v0) / (a[j + 1] - a[j])
                sensitivity = slope * amplitude / speed_mps if speed_mps > 0.0 else math.nan
                key = (float(not steerable(sensitivity)), float(abs(v1 - v0)), amplitude)
                if key < best_key:
                    best_key = key
                    best = SpeedChoice(float(frequency), amplitude, float(speed_mps))
        return best

    def nearest(self, speed_mps: float) -> SpeedChoice:
        low, high = self.reachable_range()
        target = min(max(speed_mps, low), high) if math.isfinite(speed_mps) else 0.0
        choice = self.choose(target)
        assert choice is not None, "a speed inside the table's range is always bracketed"
        return choice


def _allowed_grid(limits: DriveLimits, frequency_steps: int) -> F64:
    """``frequency_steps`` frequencies spread over the allowed intervals (band edges included)."""
    grid = np.linspace(limits.min_frequency_hz, limits.max_frequency_hz, frequency_steps)
    allowed = [limits.nearest_allowed_frequency(float(f)) for f in grid]
    return np.unique(np.asarray(allowed, dtype=np.float64))


def compute_speed_table(
    plant: FeederParameters,
    limits: DriveLimits,
    frequency_steps: int = 30,
    amplitude_steps: int = 11,
    duration_s: float = 2.0,
    part: PartSpec | None = None,
) -> TableSpeedModel:
    """Simulate the plant (exact sharp model, one part from rest) at every grid point."""
    if frequency_steps < 1 or amplitude_steps < 2:
        raise ValueError("need >= 1 frequency step and >= 2 amplitude steps")
    frequencies = _allowed_grid(limits, frequency_steps)
    amplitudes = np.linspace(0.0, limits.max_amplitude_percent, amplitude_steps)
    points = [
        plant.with_changes(drive_frequency_hz=float(f), drive_amplitude_n=limits.force_n(float(a)))
        for f in frequencies
        for a in amplitudes
    ]
    summary = simulate_many(points, duration_s, part=part if part is not None else PartSpec())
    speeds = np.asarray(summary.mean_part_speed_mps, dtype=np.float64)
    return TableSpeedModel(
        frequencies, amplitudes, speeds.reshape(frequencies.size, amplitudes.size)
    )


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "feeder_ros" / "speed_tables"


def table_key(
    plant: FeederParameters,
    limits: DriveLimits,
    frequency_steps: int,
    amplitude_steps: int,
    duration_s: float,
) -> str:
    """A hash of everything the table depends on (names the cache file)."""
    content = {
        "version": TABLE_VERSION,
        "plant": plant.as_dict(),
        "limits": [
            limits.min_frequency_hz,
            limits.max_frequency_hz,
            limits.max_amplitude_percent,
            limits.full_scale_force_n,
            limits.forbidden_bands_hz,
        ],
        "grid": [frequency_steps, amplitude_steps, duration_s],
    }
    text = json.dumps(content, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def cached_speed_table(
    plant: FeederParameters,
    limits: DriveLimits,
    cache_dir: Path,
    frequency_steps: int = 30,
    amplitude_steps: int = 11,
    duration_s: float = 2.0,
    on_store_error: Callable[[OSError], None] | None = None,
) -> tuple[TableSpeedModel, Path, bool]:
    """The table from ``cache_dir`` if present for these inputs, else computed and stored.

    Returns (model, cache file, whether it was loaded). An unreadable cache file is recomputed.
    A computed table that cannot be stored (the directory not writable, the disk full) raises
    the ``OSError``, or, with ``on_store_error``, is passed to it and returned all the same (the
    computation is not thrown away for its cache).
    """
    key = table_key(plant, limits, frequency_steps, amplitude_steps, duration_s)
    path = Path(cache_dir) / f"speed_table_{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as data:
                model = TableSpeedModel(
                    data["frequencies_hz"], data["amplitudes_percent"], data["speeds_mps"]
                )
            return model, path, True
        except (OSError, KeyError, ValueError):
            pass  # damaged: recompute below
    model = compute_speed_table(plant, limits, frequency_steps, amplitude_steps, duration_s)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path, ".npz") as temporary:  # concurrent nodes never read half a file
            np.savez(
                temporary,
                frequencies_hz=model.frequencies_hz,
                amplitudes_percent=model.amplitudes_percent,
                speeds_mps=model.speeds_mps,
            )
    except OSError as error:
        if on_store_error is None:
            raise
        on_store_error(error)
    return model, path, False
