"""What a 3D view needs: each present object's mesh name, colour and pose, and their poses over
simulated time during a pick-and-place. Meshes come from sim.tabletop.meshes.shape_mesh."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.core import Scene
from sim.tabletop.colours import TABLE_RGB
from sim.tabletop.textures import mean_rgb

TABLE_TOP_Z_M = 0.0
TABLE_HALF_M = 0.6  # the table top is the square [-0.6, 0.6]^2 at z = 0 (matches the model)
TABLE_THICKNESS_M = 0.04
TABLE_RGBA = (*(c / 255 for c in TABLE_RGB), 1.0)


@dataclass(frozen=True)
class ObjectPose:
    """One present object: shape (a key of shape_mesh), colour name and its mean RGBA in
    [0, 1], position (3,) metres and orientation quat (w, x, y, z) of its body frame."""

    slot: str
    shape: str
    colour: str
    rgba: tuple[float, float, float, float]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]


def rgba(colour: str) -> tuple[float, float, float, float]:
    """A colour's display RGBA in [0, 1] (textures: their mean colour)."""
    r, g, b = mean_rgb(colour)
    return (r / 255, g / 255, b / 255, 1.0)


def object_poses(scene: Scene) -> list[ObjectPose]:
    """The present objects of a scene, in slot order (no MuJoCo needed)."""
    out = []
    for o in scene.objects:
        if not o.present:
            continue
        p = o.pos
        assert len(p) == 7, f"tabletop Obj.pos is (x, y, z, qw, qx, qy, qz), got {p}"
        colour = o.value("colour")
        out.append(
            ObjectPose(
                o.slot,
                o.value("shape"),
                colour,
                rgba(colour),
                (p[0], p[1], p[2]),
                (p[3], p[4], p[5], p[6]),
            )
        )
    return out


def step_with_frames(world, scene: Scene, action, *, every: int = 5):
    """Simulate one pick-and-place on `world` (a TabletopWorld), recording poses.

    Returns (frames, final scene) where frames is a sim.tabletop.physics.Frames:
    slots (K,), times_s float (F,), pos float (F, K, 3), quat float (F, K, 4) (w, x, y, z),
    picked (the carried slot or None). F grows with the simulated time (every 5 steps of 4 ms:
    one frame per 20 ms).
    """
    return world.step_with_frames(scene, np.asarray(action, float), every=every)
