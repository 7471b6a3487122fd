"""Writing matplotlib figures (Agg canvas, PNG) without leaving half-written files, and reducing
long series to what a figure can show (:func:`envelope`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from feeder_ros.atomic_files import atomic_path

__all__ = ["ENVELOPE_BINS", "envelope", "save_figure"]

#: a series with more samples than twice this is drawn as its envelope (a figure is about 900 px
#: wide: a line through 600,000 samples of a 30 Hz vibration is a solid block)
ENVELOPE_BINS = 1000

F64 = npt.NDArray[np.float64]


def save_figure(figure: Figure, path: Path) -> Path:
    """Write ``figure`` as PNG to ``path`` through a temporary file beside it and a rename."""
    path = Path(path)
    FigureCanvasAgg(figure)
    with atomic_path(path, ".png") as temporary:
        figure.savefig(temporary, dpi=110, format="png")
    return path


def envelope(t: npt.ArrayLike, y: npt.ArrayLike, bins: int = ENVELOPE_BINS) -> tuple[F64, F64, F64]:
    """``(t_mid, lowest, highest)`` of ``y`` (n,) or (n, k) over ``bins`` equal spans of the
    sorted times ``t`` (n,): what a plot of a long series can show. NaN samples (a part that has
    left) are left out; a span with none is NaN. Series of at most ``2 * bins`` samples come
    back as they are (``lowest`` and ``highest`` both ``y``)."""
    times = np.asarray(t, dtype=np.float64)
    values = np.asarray(y, dtype=np.float64)
    if times.size <= 2 * bins:
        return times, values, values
    edges = np.linspace(times[0], times[-1], bins + 1)
    starts = np.searchsorted(times, edges[:-1], side="left")
    keep = np.append(starts[1:] > starts[:-1], True)  # spans holding samples
    starts = starts[keep]
    middle = 0.5 * (edges[:-1] + edges[1:])[keep]
    with np.errstate(invalid="ignore"):
        lowest = np.fmin.reduceat(values, starts, axis=0)
        highest = np.fmax.reduceat(values, starts, axis=0)
    return middle, lowest, highest
