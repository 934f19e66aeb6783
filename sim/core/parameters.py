"""Continuous scene parameters: what a scene can vary that its concept space does not
enumerate (an object's position), each named with its range in the world's own coordinates.

A world that has them declares `World.scene_parameters` (a tuple of SceneParameter) and implements
`World.with_parameters(scene, values)` (the scene with them set; InvalidScene where the values
leave a scene no task could start from: out of range, objects overlapping) and
`World.parameters_of(scene)` (the values read back). A world without them declares none.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.core.errors import UserError


class InvalidScene(UserError):
    """Parameter values that give no valid scene (out of range, objects overlapping)."""


@dataclass(frozen=True)
class SceneParameter:
    """One continuous scene parameter: `name` (e.g. "goal.x"), its range [low, high] and its
    unit ("m", "units": the world's own coordinates)."""

    name: str
    low: float
    high: float
    unit: str = ""

    def to_dict(self) -> dict:
        return {"name": self.name, "low": self.low, "high": self.high, "unit": self.unit}


def checked(params: Sequence[SceneParameter], values: Sequence[float]) -> tuple[float, ...]:
    """The values as floats, one per parameter, finite and within range; else InvalidScene."""
    if len(values) != len(params):
        raise InvalidScene(
            f"{len(params)} values wanted ({', '.join(p.name for p in params)}), got {len(values)}"
        )
    out = tuple(float(v) for v in values)
    for p, v in zip(params, out, strict=True):
        if not math.isfinite(v) or not p.low <= v <= p.high:
            raise InvalidScene(f"{p.name} = {v} is outside [{p.low}, {p.high}] {p.unit}".rstrip())
    return out


def keep_apart(points: dict[str, Sequence[float]], clearance: float, unit: str = "") -> None:
    """InvalidScene unless every two named (x, y) points are at least `clearance` apart."""
    names = list(points)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            d = math.hypot(points[a][0] - points[b][0], points[a][1] - points[b][1])
            if d < clearance:
                raise InvalidScene(
                    f"{a} and {b} are {d:.3g} {unit} apart, closer than {clearance} {unit}: "
                    "they would overlap".replace("  ", " ")
                )


def uniform(params: Sequence[SceneParameter], rng: np.random.Generator, n: int) -> np.ndarray:
    """float64 (n, P): values drawn uniformly within each parameter's range."""
    low = np.array([p.low for p in params], np.float64)
    high = np.array([p.high for p in params], np.float64)
    return low + rng.random((n, len(params))) * (high - low)


__all__ = ["InvalidScene", "SceneParameter", "checked", "keep_apart", "uniform"]
