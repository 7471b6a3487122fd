"""Writing matplotlib figures (Agg canvas, PNG) without leaving half-written files."""

from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from feeder_ros.atomic_files import atomic_path

__all__ = ["save_figure"]


def save_figure(figure: Figure, path: Path) -> Path:
    """Write ``figure`` as PNG to ``path`` through a temporary file beside it and a rename."""
    path = Path(path)
    FigureCanvasAgg(figure)
    with atomic_path(path, ".png") as temporary:
        figure.savefig(temporary, dpi=110, format="png")
    return path
