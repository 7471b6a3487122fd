"""Where the drive's speed model comes from (ROS-free): the plant's physics table, an identified
model file, or none; each with the one line ``/diagnostics`` and the configure log show.

:func:`build_speed_model` takes the drive interface's ``speed_model_*`` settings
(:class:`SpeedModelSource`): disabled gives no model; a file gives the identified model's speeds
on the allowed frequencies (for the plant's part mass when the file holds several); otherwise the
physics table of the plant, loaded from the cache or simulated and stored. A table not yet cached
is simulated on ``threads`` threads so that a core stays free for the live nodes beside the drive
(a 2-core machine starved the simulator and the estimator).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.speed_model import SpeedModel, cached_speed_table, default_cache_dir
from feeder_ros.identification.speed_model_file import identified_speed_table, load_speed_model
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import limited_threads

__all__ = ["SpeedModelSource", "build_speed_model", "physics_speed_table"]


@dataclass(frozen=True)
class SpeedModelSource:
    """The drive interface's ``speed_model_*`` parameters; empty strings mean "not given"."""

    enabled: bool = True
    file: str = ""
    cache_dir: str = ""
    frequency_steps: int = 30
    amplitude_steps: int = 11
    duration_s: float = 2.0
    threads: int = 1


def physics_speed_table(
    plant: FeederParameters,
    limits: DriveLimits,
    source: SpeedModelSource,
    on_store_error: Callable[[OSError], None] | None = None,
) -> tuple[SpeedModel, str]:
    """The physics table for ``plant`` (from the cache, or simulated and stored) and its line."""
    cache = Path(source.cache_dir).expanduser() if source.cache_dir else default_cache_dir()
    with limited_threads(source.threads):
        model, path, loaded = cached_speed_table(
            plant,
            limits,
            cache,
            source.frequency_steps,
            source.amplitude_steps,
            source.duration_s,
            on_store_error=on_store_error,
        )
    low, high = model.reachable_range()
    origin = "loaded" if loaded else "computed"
    return model, f"{origin} table {path.name}, {low:.4g}..{high:.4g} m/s"


def _identified_speed_model(
    path: Path, limits: DriveLimits, part_mass_kg: float, frequency_steps: int
) -> tuple[SpeedModel, str]:
    model_file = load_speed_model(path.expanduser())
    model = identified_speed_table(
        model_file, limits, part_mass_kg=part_mass_kg, frequency_steps=frequency_steps
    )
    low, high = model.reachable_range()
    fits = len(model_file.entries)
    return model, f"identified model {path.name} ({fits} fits), {low:.4g}..{high:.4g} m/s"


def build_speed_model(
    source: SpeedModelSource,
    plant: FeederParameters,
    limits: DriveLimits,
    on_store_error: Callable[[OSError], None] | None = None,
) -> tuple[SpeedModel | None, str]:
    """``(model, line)``: none when disabled. A file that is not a speed model raises
    IdentificationError (a ValueError), an unreadable one OSError: the configure fails."""
    if not source.enabled:
        return None, "disabled"
    if source.file:
        return _identified_speed_model(
            Path(source.file), limits, plant.part_mass_kg, source.frequency_steps
        )
    return physics_speed_table(plant, limits, source, on_store_error)
