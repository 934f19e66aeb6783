"""A matplotlib figure written as a PNG file, atomically and without a timestamp or version."""

from __future__ import annotations

from pathlib import Path

from sim.core import files


def save_figure(fig, path: Path, *, dpi: int = 120, tight: bool = True) -> None:
    """Write `fig` (a matplotlib Figure, given an Agg canvas here) to `path` as a PNG; `tight`
    crops it to what is drawn. The same figure gives the same bytes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with files.atomic_path(path) as tmp:
        fig.savefig(
            tmp,
            format="png",
            dpi=dpi,
            bbox_inches="tight" if tight else None,
            metadata={"Software": None},
        )
