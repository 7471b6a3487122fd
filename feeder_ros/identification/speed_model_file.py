"""The identified speed model on disk (YAML), and the speed table target-speed mode drives from.

One file holds one transfer function per identified setting (drive amplitude, part mass), each
fitted over a frequency range (Eqs. 21-23, :mod:`feeder_ros.identification.rational_fit`)::

    format: feeder_ros/identified_speed_model
    version: 1
    units: {frequency: Hz, speed: m/s, force: N, mass: kg, amplitude: percent, s: rad/s}
    model_form: G(s) = gain * prod(s - zeros) / prod(s - poles); speed = |G(j 2 pi f)| * amplitude_n
    full_scale_force_n: 100.0
    source: sweep of feeder_1, 2026-05-04 (bag sweep_41pct)
    entries:
    - amplitude_percent: 41.0
      amplitude_n: 41.0              # = amplitude_percent / 100 * full_scale_force_n
      part_mass_kg: 0.031
      frequency_range_hz: [38.0, 58.0]
      fit_percent: 94.5
      model: {gain: 5000.0, zeros: [[-188.5, 0.0]], poles: [[-23.6, 294.4], [-23.6, -294.4]]}

The drive interface turns it into a :class:`~feeder_ros.drive.speed_model.TableSpeedModel` with
:func:`identified_speed_table`, so its existing target-speed logic is reused unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import yaml

from feeder_ros.atomic_files import atomic_text
from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.speed_model import TableSpeedModel
from feeder_ros.identification.rational_fit import (
    F64,
    FitResult,
    IdentificationError,
    RationalModel,
    _real,
)
from feeder_ros.yaml_files import YamlFileError, read_yaml

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "UNITS",
    "ModelEntry",
    "SpeedModelFile",
    "identified_speed_table",
    "load_speed_model",
    "save_speed_model",
]

FORMAT: Final = "feeder_ros/identified_speed_model"
FORMAT_VERSION: Final = 1
UNITS: Final[Mapping[str, str]] = {
    "frequency": "Hz",
    "speed": "m/s",
    "force": "N",
    "mass": "kg",
    "amplitude": "percent",
    "s": "rad/s",
}
MODEL_FORM: Final = (
    "G(s) = gain * prod(s - zeros) / prod(s - poles); speed = |G(j 2 pi f)| * amplitude_n"
)
_FORCE_RTOL: Final = 1e-6  # amplitude_n against amplitude_percent / 100 * full_scale_force_n


@dataclass(frozen=True)
class ModelEntry:
    """One identified setting: G(s) for this drive amplitude and part mass, valid over
    ``frequency_range_hz`` (the swept band). Validated on construction."""

    amplitude_percent: float
    amplitude_n: float
    part_mass_kg: float
    frequency_range_hz: tuple[float, float]
    fit_percent: float
    model: RationalModel

    def __post_init__(self) -> None:
        amplitude = _real("amplitude_percent", self.amplitude_percent)
        if not 0.0 < amplitude <= 100.0:
            raise IdentificationError(f"amplitude_percent={amplitude!r} must be in (0, 100] %")
        for name in ("amplitude_n", "part_mass_kg"):
            value = _real(name, getattr(self, name))
            if value <= 0.0:
                raise IdentificationError(f"{name}={value!r} must be > 0")
            object.__setattr__(self, name, value)
        band = self.frequency_range_hz
        if not isinstance(band, tuple | list) or len(band) != 2:
            raise IdentificationError(f"frequency_range_hz={band!r} is not a [low, high] pair")
        low, high = _real("frequency_range_hz[0]", band[0]), _real("frequency_range_hz[1]", band[1])
        if not 0.0 < low < high:
            raise IdentificationError(
                f"frequency_range_hz=[{low!r}, {high!r}] needs 0 < low < high"
            )
        fit = _real("fit_percent", self.fit_percent)
        if fit > 100.0:
            raise IdentificationError(f"fit_percent={fit!r} cannot exceed 100")
        if not isinstance(self.model, RationalModel):
            raise IdentificationError(f"model={self.model!r} is not a RationalModel")
        object.__setattr__(self, "amplitude_percent", amplitude)
        object.__setattr__(self, "frequency_range_hz", (low, high))
        object.__setattr__(self, "fit_percent", fit)

    @classmethod
    def from_fit(cls, fit: FitResult, amplitude_percent: float, part_mass_kg: float) -> ModelEntry:
        """The entry of a fit: its force amplitude, swept band and fit percentage."""
        band = (float(np.min(fit.frequency_hz)), float(np.max(fit.frequency_hz)))
        return cls(
            amplitude_percent, fit.amplitude_n, part_mass_kg, band, fit.fit_percent, fit.model
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "amplitude_percent": self.amplitude_percent,
            "amplitude_n": self.amplitude_n,
            "part_mass_kg": self.part_mass_kg,
            "frequency_range_hz": list(self.frequency_range_hz),
            "fit_percent": self.fit_percent,
            "model": self.model.to_dict(),
        }


@dataclass(frozen=True)
class SpeedModelFile:
    """The contents of a speed model file. Validated on construction: at least one entry, one
    entry per (part mass, amplitude), and every ``amplitude_n`` equal to ``amplitude_percent /
    100 * full_scale_force_n`` (relative 1e-6; the drive's force mapping)."""

    full_scale_force_n: float
    entries: tuple[ModelEntry, ...]
    source: str = ""

    def __post_init__(self) -> None:
        full_scale = _real("full_scale_force_n", self.full_scale_force_n)
        if full_scale <= 0.0:
            raise IdentificationError(f"full_scale_force_n={full_scale!r} must be > 0 N")
        if not isinstance(self.source, str):
            raise IdentificationError(f"source={self.source!r} is not text")
        entries = tuple(self.entries)
        if not entries:
            raise IdentificationError("entries is empty: the file identifies nothing")
        seen: dict[tuple[float, float], int] = {}
        for index, entry in enumerate(entries):
            if not isinstance(entry, ModelEntry):
                raise IdentificationError(f"entries[{index}]={entry!r} is not a ModelEntry")
            expected = entry.amplitude_percent / 100.0 * full_scale
            if not math.isclose(entry.amplitude_n, expected, rel_tol=_FORCE_RTOL):
                raise IdentificationError(
                    f"entries[{index}].amplitude_n={entry.amplitude_n!r} N does not match "
                    f"amplitude_percent={entry.amplitude_percent:g} % of full_scale_force_n="
                    f"{full_scale:g} N (= {expected:g} N)"
                )
            key = (entry.part_mass_kg, entry.amplitude_percent)
            if key in seen:
                raise IdentificationError(
                    f"entries[{seen[key]}] and entries[{index}] are both for part_mass_kg="
                    f"{key[0]:g} at amplitude_percent={key[1]:g}: one model per setting"
                )
            seen[key] = index
        object.__setattr__(self, "full_scale_force_n", full_scale)
        object.__setattr__(self, "entries", entries)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "units": dict(UNITS),
            "model_form": MODEL_FORM,
            "full_scale_force_n": self.full_scale_force_n,
            "source": self.source,
            "entries": [entry.to_dict() for entry in self.entries],
        }


# --------------------------------------------------------------------------- reading


def _field(mapping: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in mapping:
        raise IdentificationError(f"missing field {where}{key}")
    return mapping[key]


def _mapping(value: object, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise IdentificationError(f"{where} must be a mapping; got {value!r}")
    return value


def _check_header(document: Mapping[str, Any]) -> None:
    kind = _field(document, "format", "")
    if kind != FORMAT:
        raise IdentificationError(f"format={kind!r} is not {FORMAT!r}")
    version = _field(document, "version", "")
    if isinstance(version, bool) or version != FORMAT_VERSION:
        raise IdentificationError(
            f"version={version!r} is not supported (this reader reads version {FORMAT_VERSION})"
        )
    units = _mapping(_field(document, "units", ""), "units")
    for key, unit in UNITS.items():
        value = _field(units, key, "units.")
        if value != unit:
            raise IdentificationError(f"units.{key}={value!r} is not {unit!r}")


def _entry_from(value: object, index: int) -> ModelEntry:
    where = f"entries[{index}]"
    data = _mapping(value, where)
    numbers = {
        name: _real(f"{where}.{name}", _field(data, name, f"{where}."))
        for name in ("amplitude_percent", "amplitude_n", "part_mass_kg", "fit_percent")
    }
    band = _field(data, "frequency_range_hz", f"{where}.")
    if not isinstance(band, list) or len(band) != 2:
        raise IdentificationError(f"{where}.frequency_range_hz={band!r} is not a [low, high] pair")
    low = _real(f"{where}.frequency_range_hz[0]", band[0])
    high = _real(f"{where}.frequency_range_hz[1]", band[1])
    model_data = _mapping(_field(data, "model", f"{where}."), f"{where}.model")
    try:
        model = RationalModel.from_dict(model_data)
    except IdentificationError as exc:
        raise IdentificationError(f"{where}.model: {exc}") from None
    try:
        return ModelEntry(
            numbers["amplitude_percent"],
            numbers["amplitude_n"],
            numbers["part_mass_kg"],
            (low, high),
            numbers["fit_percent"],
            model,
        )
    except IdentificationError as exc:
        raise IdentificationError(f"{where}: {exc}") from None


def _from_document(document: object) -> SpeedModelFile:
    if document is None:
        raise IdentificationError("the file is empty")
    data = _mapping(document, "the top level")
    _check_header(data)
    full_scale = _real("full_scale_force_n", _field(data, "full_scale_force_n", ""))
    source = _field(data, "source", "")
    if not isinstance(source, str):
        raise IdentificationError(f"source={source!r} is not text")
    entries = _field(data, "entries", "")
    if not isinstance(entries, list):
        raise IdentificationError(f"entries={entries!r} is not a list")
    parsed = tuple(_entry_from(value, index) for index, value in enumerate(entries))
    return SpeedModelFile(full_scale, parsed, source)


def load_speed_model(path: Path) -> SpeedModelFile:
    """Read and validate a speed model file; IdentificationError naming the file, the field and
    the value on any problem (unreadable, not YAML, wrong format or version, missing field, NaN,
    unstable pole, inconsistent force, ...)."""
    path = Path(path)
    try:
        document = read_yaml(path)
    except OSError as exc:
        raise IdentificationError(f"{path}: cannot read the speed model: {exc}") from None
    except YamlFileError as exc:
        raise IdentificationError(str(exc)) from None
    try:
        return _from_document(document)
    except IdentificationError as exc:
        raise IdentificationError(f"{path}: {exc}") from None


# --------------------------------------------------------------------------- writing


def save_speed_model(path: Path, model_file: SpeedModelFile) -> None:
    """Write ``model_file`` to ``path`` atomically: the YAML is produced and checked to read back
    as the same model first, then written to a temporary file in the same directory, flushed to
    disk and renamed over ``path`` (``os.replace``). A failure at any step leaves an existing
    file untouched and no temporary file behind."""
    path = Path(path)
    if not isinstance(model_file, SpeedModelFile):
        raise IdentificationError(f"model_file={model_file!r} is not a SpeedModelFile")
    text = yaml.safe_dump(model_file.to_dict(), sort_keys=False, default_flow_style=None, width=100)
    try:
        _from_document(yaml.safe_load(text))
    except IdentificationError as exc:
        raise IdentificationError(
            f"{path}: not saved, the model does not validate: {exc}"
        ) from None
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_text(path, durable=True) as handle:
        handle.write(text)


# --------------------------------------------------------------------------- the speed table


def _entries_for_mass(model_file: SpeedModelFile, part_mass_kg: float | None) -> list[ModelEntry]:
    """The entries of the identified mass nearest to ``part_mass_kg`` (ties: the lighter one);
    None is allowed when the file identifies a single mass."""
    masses = sorted({entry.part_mass_kg for entry in model_file.entries})
    if part_mass_kg is None:
        if len(masses) > 1:
            listed = ", ".join(f"{mass:g}" for mass in masses)
            raise IdentificationError(
                f"the model identifies part masses {listed} kg: part_mass_kg must say which"
            )
        chosen = masses[0]
    else:
        mass = _real("part_mass_kg", part_mass_kg)
        if mass <= 0.0:
            raise IdentificationError(f"part_mass_kg={mass!r} must be > 0")
        chosen = min(masses, key=lambda m: (abs(m - mass), m))
    return [entry for entry in model_file.entries if entry.part_mass_kg == chosen]


def _allowed_frequencies(limits: DriveLimits, low: float, high: float, steps: int) -> F64:
    """``steps`` frequencies over the identified range [low, high] within the drive's range, each
    moved to the nearest allowed set point (forbidden bands: to their edges), and kept only if
    that is still inside [low, high]."""
    start, stop = max(low, limits.min_frequency_hz), min(high, limits.max_frequency_hz)
    if start > stop:
        raise IdentificationError(
            f"the identified range {low:g}-{high:g} Hz does not overlap the drive's "
            f"{limits.min_frequency_hz:g}-{limits.max_frequency_hz:g} Hz"
        )
    grid = np.linspace(start, stop, steps) if steps > 1 else np.asarray([0.5 * (start + stop)])
    allowed = {limits.nearest_allowed_frequency(float(f)) for f in grid}
    inside = sorted(f for f in allowed if low <= f <= high)
    if not inside:
        bands = ", ".join(f"{a:g}-{b:g}" for a, b in limits.forbidden_bands_hz)
        raise IdentificationError(
            f"no allowed frequency inside the identified range {low:g}-{high:g} Hz "
            f"(forbidden bands: {bands} Hz)"
        )
    return np.asarray(inside, dtype=np.float64)


def identified_speed_table(
    model_file: SpeedModelFile,
    limits: DriveLimits,
    part_mass_kg: float | None = None,
    frequency_steps: int = 60,
) -> TableSpeedModel:
    """The speed table of the identified models, for the drive interface's target-speed mode.

    Rows: allowed set-point frequencies (``frequency_steps`` spread over the part of the
    identified range, common to all used entries, that lies within the drive's limits; those in
    a forbidden band moved to its edges). Columns: the identified amplitudes (percent) of the
    part mass nearest to ``part_mass_kg`` (or the only one) that the drive may use (<=
    ``limits.max_amplitude_percent``), at least 2. Speeds: ``|G_a(j 2 pi f)| * amplitude_n(a)``.
    Between the identified amplitudes the table interpolates linearly; below the lowest and
    above the highest there is no model, so those speeds are not reachable.
    """
    if isinstance(frequency_steps, bool) or not isinstance(frequency_steps, int):
        raise IdentificationError(f"frequency_steps={frequency_steps!r} is not an integer")
    if frequency_steps < 1:
        raise IdentificationError(f"frequency_steps={frequency_steps} must be >= 1")
    entries = _entries_for_mass(model_file, part_mass_kg)
    usable = sorted(
        (e for e in entries if e.amplitude_percent <= limits.max_amplitude_percent),
        key=lambda e: e.amplitude_percent,
    )
    if len(usable) < 2:
        identified = ", ".join(f"{e.amplitude_percent:g}" for e in entries)
        raise IdentificationError(
            f"part mass {entries[0].part_mass_kg:g} kg: amplitudes {identified} % identified, "
            f"{len(usable)} within max_amplitude_percent={limits.max_amplitude_percent:g}; "
            "a speed table needs >= 2"
        )
    low = max(e.frequency_range_hz[0] for e in usable)
    high = min(e.frequency_range_hz[1] for e in usable)
    if low > high:
        raise IdentificationError(
            "the identified frequency ranges of the amplitudes "
            f"{', '.join(f'{e.amplitude_percent:g}' for e in usable)} % have no common part"
        )
    frequencies = _allowed_frequencies(limits, low, high, frequency_steps)
    speeds = np.column_stack([e.model.magnitude(frequencies) * e.amplitude_n for e in usable])
    amplitudes = [e.amplitude_percent for e in usable]
    return TableSpeedModel(frequencies, amplitudes, speeds)
