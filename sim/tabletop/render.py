"""Phi^-1 for the tabletop: one orthographic top-down camera, one GL context, 80x80x3 frames."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
# Mesa's software rasteriser (llvmpipe, what EGL gives without a GPU) draws on the calling
# thread: for 80x80 frames its worker threads cost more than they give (0.39 vs 0.56 ms a
# frame on 2 cores, the same pixels); set before the first GL context, ignored by other drivers
os.environ.setdefault("LP_NUM_THREADS", "0")

from collections.abc import Sequence
from contextlib import contextmanager

import mujoco
import numpy as np

from sim.core import Scene
from sim.tabletop.model import GROUP_SHOWN, Table

SIZE_PX = 80


def _release_egl() -> None:
    """Make no EGL context current in this thread (nothing to do for other GL backends)."""
    if os.environ.get("MUJOCO_GL") != "egl":
        return
    from OpenGL import EGL

    display = EGL.eglGetCurrentDisplay()
    if display != EGL.EGL_NO_DISPLAY:
        EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)


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
        _release_egl()  # the constructor left the context current in this thread
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
        with self._current():
            for i, s in enumerate(scenes):
                self.table.load(s)
                mujoco.mj_kinematics(m, d)
                mujoco.mj_camlight(m, d)
                self.render_current(out=out[i])
        return out

    @contextmanager
    def _current(self):
        """Hold the GL context for one batch and let it go after, so that the next batch may
        come from another thread (an EGL context is current in one thread at a time)."""
        ctx = getattr(self.renderer, "_gl_context", None)
        if ctx is not None:
            ctx.make_current()
        try:
            yield
        finally:
            _release_egl()

    def close(self) -> None:
        self.renderer.close()
