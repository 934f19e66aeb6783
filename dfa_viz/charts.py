"""Charts drawn as images for the recording (matplotlib, headless): what Rerun's own views
cannot label, or would show only on another timeline. Each returns uint8 (H, W, 3).

    loss_chart        the finetuning loss over gradient steps, log scale
    success_chart     success before -> after, on the shift and over all the user wants
    distance_bars     one-step worlds: each rollout's action distance against epsilon
    candidates_chart  one-step worlds: every candidate's distance, sorted, epsilon drawn

The colours of the rollouts are the page's too (COLOURS).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np

COLOURS = {
    "failed": "#d9480f",
    "demonstration": "#495057",
    "counterfactual": "#2f9e44",
    "finetuned": "#1c7ed6",
    "epsilon": "#868e96",
    "step": "#212529",
}
SIZE_IN = (4.8, 3.0)  # figure size in inches, at 100 dpi


def _rgb(hex_colour: str) -> list[int]:
    h = hex_colour.lstrip("#")
    return [int(h[i : i + 2], 16) for i in (0, 2, 4)]


def rgb(name: str) -> list[int]:
    """The colour of a rollout (or "epsilon") as [r, g, b] 0-255."""
    return _rgb(COLOURS.get(name, "#495057"))


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=SIZE_IN, dpi=100)
    ax.grid(alpha=0.3)
    return plt, fig, ax


def _image(plt, fig) -> np.ndarray:
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    from PIL import Image

    return np.asarray(Image.open(buf).convert("RGB"))


def loss_chart(losses: Sequence[float]) -> np.ndarray:
    plt, fig, ax = _figure()
    y = np.maximum(np.asarray(losses, np.float64), 1e-12)
    ax.plot(np.arange(len(y)), y, color=COLOURS["finetuned"], lw=1.5)
    ax.set_yscale("log")
    ax.set_xlabel("finetuning step")
    ax.set_ylabel("loss (log scale)")
    ax.set_title("finetuning loss")
    return _image(plt, fig)


def success_chart(before: tuple[float, float], after: tuple[float, float], n: int) -> np.ndarray:
    """Bars of (on the shift, over all the user wants) before and after finetuning."""
    plt, fig, ax = _figure()
    groups = ("with the shift", "all the user wants")
    x = np.arange(2)
    for k, (label, vals, colour) in enumerate(
        (("before", before, COLOURS["failed"]), ("after", after, COLOURS["finetuned"]))
    ):
        bars = ax.bar(x + (k - 0.5) * 0.38, vals, 0.36, label=label, color=colour)
        ax.bar_label(bars, labels=[f"{v:.0%}" for v in vals], padding=2, fontsize=9)
    ax.set_xticks(x, groups)
    ax.set_ylim(0, 1.15)
    ax.set_ylabel(f"success on {n} fresh tasks")
    ax.set_title("success before → after finetuning")
    ax.legend(loc="upper left", fontsize=8, ncol=2)
    return _image(plt, fig)


def distance_bars(distances: Mapping[str, float], epsilon: float) -> np.ndarray:
    plt, fig, ax = _figure()
    names = list(distances)
    vals = [distances[k] for k in names]
    bars = ax.bar(names, vals, color=[COLOURS.get(k, "#495057") for k in names])
    ax.bar_label(bars, labels=[f"{v:.3f}" for v in vals], padding=2, fontsize=9)
    ax.axhline(epsilon, color=COLOURS["epsilon"], ls="--", lw=1, label=f"ε = {epsilon:g}")
    ax.set_ylabel("action distance (L1)")
    ax.set_title("distance to the demonstration's action")
    ax.legend(fontsize=8)
    return _image(plt, fig)


def candidates_chart(totals: Sequence[float], valid: Sequence[bool], epsilon: float) -> np.ndarray:
    """Every candidate's distance to the demonstration, sorted; green: within ε (follows the
    demonstration), red: not."""
    plt, fig, ax = _figure()
    order = np.argsort(np.asarray(totals, np.float64), kind="stable")
    y = np.asarray(totals, np.float64)[order]
    ok = np.asarray(valid, bool)[order]
    x = np.arange(len(y))
    ax.scatter(x[~ok], y[~ok], s=4, color=COLOURS["failed"], label="does not follow it")
    ax.scatter(x[ok], y[ok], s=10, color=COLOURS["counterfactual"], label="follows it (< ε)")
    ax.axhline(epsilon, color=COLOURS["epsilon"], ls="--", lw=1, label=f"ε = {epsilon:g}")
    ax.set_xlabel(f"candidate edits, closest first ({len(y)} tried)")
    ax.set_ylabel("action distance (L1)")
    ax.set_title("every edit the search tried")
    ax.legend(fontsize=8)
    return _image(plt, fig)
