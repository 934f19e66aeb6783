"""A results folder of one JSON record per world (`dfa experiment search`, `dfa experiment
positions`): the records in the paper's order, and a figure with its interval as table text."""

from __future__ import annotations

import json
from pathlib import Path

from sim import PAPER_WORLDS

PAPER_ORDER = {name: i for i, name in enumerate(PAPER_WORLDS)}


def world_order(world: str) -> tuple[int, str]:
    """A sort key that puts the paper's worlds first, in its order, then the others by name."""
    return (PAPER_ORDER.get(world, len(PAPER_WORLDS)), world)


def load_records(out: Path) -> list[dict]:
    """Every world's JSON in the folder, in the paper's order then by name."""
    records = [json.loads(f.read_text()) for f in sorted(out.glob("*.json"))]
    return sorted(records, key=lambda r: world_order(r["world"]))


def figure_text(f: dict, digits: int, *, to: str = "–", grouped: bool = True) -> str:
    """{"mean", "low", "high"} as "mean (low<to>high)", or the mean alone where the interval
    is a point; "–" where the mean is not a number. `grouped`: thousands separated by commas."""
    mean, low, high = f["mean"], f["low"], f["high"]
    if mean != mean:
        return "–"
    g = "," if grouped else ""
    if abs(high - low) < 1e-9:
        return f"{mean:{g}.{digits}f}"
    return f"{mean:{g}.{digits}f} ({low:{g}.{digits}f}{to}{high:{g}.{digits}f})"
