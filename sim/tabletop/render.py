"""Phi^-1 for the tabletop: one orthographic top-down camera, one GL context, 80x80x3 frames."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from sim.core import Scene
from sim.mjworld.gl import current, release_egl  # sets MUJOCO_GL and LP_NUM_THREADS first
from sim.tabletop.model import GROUP_SHOWN, Table

SIZE_PX = 80


class TopCamera:
    """Renders scenes of one Table through its "top" camera with a single mujoco.Renderer.

    Shadows, reflections, skybox and fog are off; only geom group 0 (the shown display meshes
    and the table) is drawn.
    """

    def __init__(self, table: Table, size_px: int = SIZE_PX) -> None:
        self.table = table
        self.size_px = size_px
        # an offscreen buffer the size of the frame: the same pixels, 15% less time per frame
        # than MuJoCo's default 640x480 (llvmpipe clears and resolves the whole buffer)
        table.model.vis.global_.offwidth = size_px
        table.model.vis.global_.offheight = size_px
        self.renderer = mujoco.Renderer(table.model, size_px, size_px, max_geom=64)
        release_egl()  # the constructor left the context current in this thread
        self.option = mujoco.MjvOption()
        self.option.geomgroup[:] = 0
        self.option.geomgroup[GROUP_SHOWN] = 1
        self.option.sitegroup[:] = 0
        self.camera = mujoco.mj_name2id(table.model, mujoco.mjtObj.mjOBJ_CAMERA, "top")
        flags = self.renderer.scene.flags
        for f in (
            mujoco.mjtRndFlag.mjRND_SHADOW,
            mujoco.mjtRndFlag.mjRND_REFLECTION,
            mujoco.mjtRndFlag.mjRND_SKYBOX,
            mujoco.mjtRndFlag.mjRND_FOG,
            mujoco.mjtRndFlag.mjRND_HAZE,
        ):
            flags[int(f)] = 0

    def render_current(self, out: np.ndarray | None = None) -> np.ndarray:
        """Frame of whatever the table's data holds now (kinematics already computed)."""
        self.renderer.update_scene(self.table.data, camera=self.camera, scene_option=self.option)
        return self.renderer.render(out=out)  # (H, W, 3) uint8

    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3): each scene written into the one model, then drawn."""
        m, d = self.table.model, self.table.data
        out = np.empty((len(scenes), self.size_px, self.size_px, 3), np.uint8)
        with current(self.renderer):
            for i, s in enumerate(scenes):
                self.table.load(s)
                mujoco.mj_kinematics(m, d)
                mujoco.mj_camlight(m, d)
                self.render_current(out=out[i])
        return out

    def close(self) -> None:
        self.renderer.close()
