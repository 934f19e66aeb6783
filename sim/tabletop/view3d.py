"""The tabletop's 3D scene (World.view3d): the same procedural meshes MuJoCo simulates and
renders, each object's pose, and the poses through a simulated pick-and-place. Meshes (trimesh)
and MuJoCo load when first asked for."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim.core import Scene
from sim.core.view3d import Frames, Look, ObjectPose, View3D
from sim.tabletop.colours import TABLE_RGB, is_plain
from sim.tabletop.pose import TABLE_HALF_M, TABLE_THICKNESS_M, object_poses, rgba
from sim.tabletop.tasks import VIEW_HALF_M

ARROW_Z_M = 0.15  # the action arrow floats this high above the table


class TabletopView3D(View3D):
    table_half_m = TABLE_HALF_M
    table_thickness_m = TABLE_THICKNESS_M
    table_rgb = TABLE_RGB
    view_half_m = VIEW_HALF_M
    plays_actions = True  # one action: a carry and the settling, seconds of simulated time

    def __init__(self, world) -> None:
        self._world = world  # the TabletopWorld whose physics plays actions out

    def poses(self, scene: Scene) -> list[ObjectPose]:
        return object_poses(scene)

    def mesh(self, shape: str):
        from sim.tabletop.meshes import shape_mesh

        return shape_mesh(shape)

    def look(self, shape: str, colour: str) -> Look:
        from sim.tabletop import textures as T

        if is_plain(colour):
            return Look(rgba(colour))
        return Look(rgba(colour), T.texture(colour), T.TEX_M)

    def arrow(self, scene: Scene, action: Sequence[float], after: Scene):
        """From the pick point to the place point, ARROW_Z_M above the table."""
        a = [float(v) for v in action]
        return (a[0], a[1], ARROW_Z_M), (a[2] - a[0], a[3] - a[1], 0.0)

    def frames(self, scene: Scene, action: Sequence[float], *, every: int) -> Frames:
        frames, _ = self._world.step_with_frames(scene, np.asarray(action, float), every=every)
        return frames
