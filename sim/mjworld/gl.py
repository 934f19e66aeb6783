"""One GL context per renderer, usable from any thread: MuJoCo's EGL contexts are current in
one thread at a time, so each batch of frames takes the context and lets it go after; and the
cameras a renderer draws from."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
# Mesa's software rasteriser (llvmpipe, what EGL gives without a GPU) draws on the calling
# thread: for frames of a few thousand pixels its worker threads cost more than they give
# (0.39 vs 0.56 ms a frame on 2 cores, the same pixels); set before the first GL context,
# ignored by other drivers
os.environ.setdefault("LP_NUM_THREADS", "0")

from collections.abc import Iterator
from contextlib import contextmanager


def release_egl() -> None:
    """Make no EGL context current in this thread (nothing to do for other GL backends)."""
    if os.environ.get("MUJOCO_GL") != "egl":
        return
    from OpenGL import EGL

    display = EGL.eglGetCurrentDisplay()
    if display != EGL.EGL_NO_DISPLAY:
        EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)


@contextmanager
def current(renderer) -> Iterator[None]:
    """Hold `renderer`'s (a mujoco.Renderer's) GL context for one batch and let it go after, so
    that the next batch may come from another thread."""
    ctx = getattr(renderer, "_gl_context", None)
    if ctx is not None:
        ctx.make_current()
    try:
        yield
    finally:
        release_egl()


def free_camera(camera: dict | str):
    """What mujoco.Renderer.update_scene takes for `camera`: a free MjvCamera set from a
    default_camera_config-like dict (distance, azimuth, elevation, lookat), or the model's
    camera of that name as it is."""
    if isinstance(camera, str):
        return camera
    import mujoco

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    for key, value in camera.items():
        if key == "lookat":
            cam.lookat[:] = value
        else:
            setattr(cam, key, value)
    return cam
