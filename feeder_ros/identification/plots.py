"""Figures of a sweep and its fits, in the style of the paper's Figs. 9 and 10.

* :func:`plot_speed_sweep` (Fig. 9): mean part speed against drive frequency, one curve per
  amplitude, one panel per part mass (the paper: speed over 8.5 cm in cm/s; here mm/s).
* :func:`plot_bode_magnitude` (Fig. 10): log-log magnitude of speed per unit force,
  ``|v| / A`` of the data (markers) and ``|G(j 2 pi f)|`` of the fitted models (lines), one panel
  per part mass, the models' peak frequencies marked.

matplotlib's object-oriented API on the Agg canvas (PNG, no display, no pyplot state). A figure is
written to a temporary file beside the target and renamed, so no half-written PNG is left.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from matplotlib import ticker
from matplotlib.figure import Figure

from feeder_ros.figures import save_figure
from feeder_ros.identification.sweep import SweepGroup, SweepResult

__all__ = ["MagnitudeModel", "plot_bode_magnitude", "plot_speed_sweep"]

GroupKey = tuple[float, float]  # (amplitude %, part mass kg)


class MagnitudeModel(Protocol):
    """What a figure needs of a fitted model (``RationalModel`` has it)."""

    def magnitude(self, f_hz: Any) -> Any: ...


def _panels(count: int) -> tuple[int, int]:
    columns = min(count, 2)
    return math.ceil(count / columns), columns


def _mass_label(mass_kg: float) -> str:
    return f"part mass {mass_kg * 1e3:g} g"


def plot_speed_sweep(result: SweepResult, path: Path, title: str = "") -> Path:
    """Fig. 9: speed [mm/s] against frequency [Hz]; usable points only (backward speeds too)."""
    masses = sorted({p.part_mass_kg for p in result.points})
    amplitudes = sorted({p.amplitude_percent for p in result.points})
    if not masses:
        raise ValueError("no points to plot")
    rows, columns = _panels(len(masses))
    figure = Figure(figsize=(6.0 * columns, 4.2 * rows), layout="constrained")
    axes = figure.subplots(rows, columns, squeeze=False, sharex=True, sharey=True)
    colors = _colors(len(amplitudes))
    for k, mass in enumerate(masses):
        ax = axes[k // columns][k % columns]
        for amplitude, color in zip(amplitudes, colors, strict=True):
            chosen = sorted(
                (p.frequency_hz, p.speed_mps)
                for p in result.points
                if p.ok and p.part_mass_kg == mass and p.amplitude_percent == amplitude
            )
            if not chosen:
                continue
            f, v = np.array(chosen).T
            ax.plot(f, v * 1e3, "o-", color=color, ms=3.5, lw=1.2, label=f"{amplitude:g} %")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(_mass_label(mass))
        ax.set_xlabel("drive frequency [Hz]")
        ax.set_ylabel("mean part speed [mm/s]")
        ax.grid(True, alpha=0.3)
        ax.legend(title="amplitude", fontsize=8, title_fontsize=8)
    for k in range(len(masses), rows * columns):
        axes[k // columns][k % columns].set_visible(False)
    figure.suptitle(title or f"speed sweep ({result.source})")
    return save_figure(figure, path)


def plot_bode_magnitude(
    groups: Sequence[SweepGroup],
    models: Mapping[GroupKey, MagnitudeModel],
    path: Path,
    peaks_hz: Mapping[GroupKey, float] | None = None,
    title: str = "",
) -> Path:
    """Fig. 10: |v|/A [m/s/N] of the data and |G(j 2 pi f)| of each group's model, log-log."""
    masses = sorted({g.part_mass_kg for g in groups})
    amplitudes = sorted({g.amplitude_percent for g in groups})
    if not masses:
        raise ValueError("no groups to plot")
    rows, columns = _panels(len(masses))
    figure = Figure(figsize=(6.0 * columns, 4.2 * rows), layout="constrained")
    axes = figure.subplots(rows, columns, squeeze=False)
    colors = dict(zip(amplitudes, _colors(len(amplitudes)), strict=True))
    for k, mass in enumerate(masses):
        ax = axes[k // columns][k % columns]
        for group in (g for g in groups if g.part_mass_kg == mass):
            color = colors[group.amplitude_percent]
            key = (group.amplitude_percent, group.part_mass_kg)
            if group.frequency_hz.size:
                ax.loglog(
                    group.frequency_hz,
                    group.speed_mps / group.amplitude_n,
                    "o",
                    color=color,
                    ms=3.5,
                    label=f"{group.amplitude_percent:g} % data",
                )
            model = models.get(key)
            if model is not None and group.frequency_hz.size:
                lo, hi = float(group.frequency_hz.min()), float(group.frequency_hz.max())
                grid: npt.NDArray[np.float64] = np.geomspace(lo / 1.15, hi * 1.15, 400)
                ax.loglog(
                    grid,
                    np.asarray(model.magnitude(grid), dtype=np.float64),
                    "-",
                    color=color,
                    lw=1.3,
                    label=f"{group.amplitude_percent:g} % model",
                )
                peak = (peaks_hz or {}).get(key)
                if peak is not None and math.isfinite(peak):
                    ax.axvline(peak, color=color, lw=0.8, ls=":")
        # a band of less than a decade: plain frequencies on the log axis, not 2 x 10^1
        ax.xaxis.set_major_locator(ticker.MaxNLocator(7))
        ax.xaxis.set_major_formatter(ticker.StrMethodFormatter("{x:g}"))
        ax.xaxis.set_minor_formatter(ticker.NullFormatter())
        ax.set_title(_mass_label(mass))
        ax.set_xlabel("drive frequency [Hz]")
        ax.set_ylabel("|speed / force| [m/s/N]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncols=2)
    for k in range(len(masses), rows * columns):
        axes[k // columns][k % columns].set_visible(False)
    figure.suptitle(title or "frequency response: data and fitted G(s)")
    return save_figure(figure, path)


def _colors(count: int) -> list[Any]:
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return [cmap(0.85 * k / max(count - 1, 1)) for k in range(count)]
