"""An episode as a LeRobotDataset holds it: T frames, each an observation and the action taken."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Episode:
    """One episode: frame t is observation t and the action taken from it (LeRobot's frames);
    the observation after the last action is not a frame.

    frames: uint8 (T, H, W, 3); actions: float32 (T, A) or int64 (T,) for a discrete world.
    success: R' met at the end (`next.success` of the last frame; False on the others).
    columns: further per-frame columns, name -> (T,) array of text (a numpy str or object
        array) or (T,) or (T, n) numbers; dfa's own are named dfa.*. LeRobot's own columns
        (timestamp, indices, next.success, next.done) are not among them.
    """

    task: str
    frames: np.ndarray  # (T, H, W, 3) uint8
    actions: np.ndarray  # (T, A) float32 | (T,) int64
    success: bool
    columns: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = len(self.frames)
        assert self.frames.dtype == np.uint8 and self.frames.ndim == 4, (
            f"frames must be uint8 (T, H, W, 3), got {self.frames.dtype} {self.frames.shape}"
        )
        assert t >= 1 and len(self.actions) == t, (
            f"{t} frames and {len(self.actions)} actions; expected one action per frame"
        )
        for name, values in self.columns.items():
            assert len(values) == t, f"column {name} has {len(values)} values for {t} frames"

    @property
    def length(self) -> int:
        return len(self.frames)

    def text(self, name: str, default: str = "") -> str:
        """A text column's value on the first frame (dfa's per-episode columns repeat it)."""
        values = self.columns.get(name)
        return default if values is None else str(values[0])
