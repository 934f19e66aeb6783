"""Trajectories: scenes, observations, actions and success; saved as .npz without pickle."""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.core import files
from sim.core.errors import UserError
from sim.core.scene import Scene


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One rollout.

    scenes: T+1 world states; observations: uint8 (T+1, H, W, 3);
    actions: float32 (T, A) for continuous worlds or int64 (T,) for discrete ones.
    """

    scenes: tuple[Scene, ...]
    observations: np.ndarray  # (T+1, H, W, 3) uint8
    actions: np.ndarray  # (T, A) float32 | (T,) int64
    success: bool

    def __post_init__(self) -> None:
        n = len(self.scenes)
        assert self.observations.shape[0] == n, (
            f"observations {self.observations.shape} must have {n} frames (one per scene)"
        )
        assert self.observations.dtype == np.uint8 and self.observations.ndim == 4, (
            f"observations must be uint8 (T+1, H, W, 3), got {self.observations.dtype} "
            f"{self.observations.shape}"
        )
        assert self.actions.shape[0] == n - 1, (
            f"actions {self.actions.shape} must have {n - 1} rows (one per transition)"
        )

    @property
    def horizon(self) -> int:
        return len(self.actions)

    def equals(self, other: Trajectory) -> bool:
        return (
            self.scenes == other.scenes
            and self.success == other.success
            and self.actions.dtype == other.actions.dtype
            and np.array_equal(self.observations, other.observations)
            and np.array_equal(self.actions, other.actions)
        )

    def save(self, path: str | Path) -> Path:
        """Write atomically as .npz (scenes as JSON text, no pickled objects)."""
        path = Path(path)
        scenes = json.dumps([s.to_dict() for s in self.scenes])
        with files.atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez_compressed(
                f,
                scenes=np.frombuffer(scenes.encode(), dtype=np.uint8),
                observations=self.observations,
                actions=self.actions,
                success=np.array(self.success),
            )
        return path

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        path = Path(path)
        expected = "an .npz with arrays scenes, observations, actions, success (Trajectory.save)"
        if not path.is_file():
            raise UserError(f"{path}: no such file; expected {expected}")
        if not zipfile.is_zipfile(path):
            raise UserError(f"{path}: not an .npz archive; expected {expected}")
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = {"scenes", "observations", "actions", "success"} - set(z.files)
                if missing:
                    raise UserError(f"{path}: missing {sorted(missing)}; expected {expected}")
                scenes_json = bytes(z["scenes"]).decode()
                obs, actions, success = z["observations"], z["actions"], bool(z["success"])
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
            if isinstance(e, UserError):
                raise
            raise UserError(
                f"{path}: not a readable trajectory ({e}); expected {expected}"
            ) from None
        try:
            scenes = tuple(Scene.from_dict(d) for d in json.loads(scenes_json))
            return cls(scenes, obs, actions, success)
        except (json.JSONDecodeError, AssertionError, TypeError, RecursionError, UserError) as e:
            raise UserError(f"{path}: malformed trajectory: {e}") from None
