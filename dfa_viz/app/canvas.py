"""The 3D view of one tab: the task's top-down image on a clickable plane (demonstrations are
given by clicking it), and, for worlds with meshes, the failed and counterfactual scenes in 3D.

The plane lies at z = 0, centred on the origin, SIZE along the longer side of the frame and
as long along the other as the frame's shape gives, seen from above with +y up the screen. viser
draws image row 0 at -y, so images are flipped vertically before they are sent.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import viser

from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View

SIZE = 12.0  # plane width and height in scene units
GHOST_RGB = (30, 160, 60)  # the counterfactual's objects: green wireframes over the solid ones


class Canvas:
    def __init__(self, client: viser.ClientHandle, state: LoopState, notify) -> None:
        self.client, self.state, self.notify = client, state, notify
        self._lock = threading.Lock()
        self.plane: viser.ImageHandle | None = None
        self._plane_shape = (SIZE, SIZE)  # (width, height) in scene units: the frame's shape
        self._shown: tuple | None = None
        self._meshes: tuple | None = None
        self._frame: tuple | None = None  # (rollout, step) the plane shows, for flat worlds
        self._mesh_nodes: dict[str, object] = {}
        self._oblique_for: tuple | None = None
        self.covered = False  # the Sweep tab's heatmap lies over the image: clicks are its own
        self.pin_camera()
        # clicks anywhere in the view (not on the plane as a clickable node, which viser would
        # paint yellow under the pointer): a click off the image can then be told so
        client.scene.on_click()(self._on_click)

    def pin_camera(self) -> None:
        """Look straight down at the plane (again: arrow keys also turn viser's camera)."""
        cam = self.client.camera
        cam.up_direction = (0.0, 1.0, 0.0)
        cam.position = (0.0, 0.0, 1.9 * SIZE)
        cam.look_at = (0.0, 0.0, 0.0)

    def oblique_camera(self) -> None:
        """Look at the plane from the front, above it at an angle (the 3D scenes)."""
        cam = self.client.camera
        cam.up_direction = (0.0, 0.0, 1.0)
        cam.position = (0.0, -1.1 * SIZE, 1.0 * SIZE)
        cam.look_at = (0.0, 0.0, 0.0)

    def refresh(self, view: View, *, force: bool = False) -> None:
        """Redraw the plane when the task or the demonstration changed."""
        run = view.record
        key = (id(run.task) if run else None, view.stage, view.demo_summary, view.version)
        with self._lock:
            if not force and self._shown is not None and key[:3] == self._shown[:3]:
                return
            new_task = self._shown is None or key[0] != self._shown[0]
            self._shown = key
            self._frame = None
            if new_task or view.demo_kind == "keys":
                self.pin_camera()
            if self._meshes_shown(view) and key[1] != (self._oblique_for or (None, None))[1]:
                self.oblique_camera()  # the 3D objects, seen at an angle once they are drawn
            self._oblique_for = key if self._meshes_shown(view) else None
            image = self.state.demo_canvas()
            if self._meshes_shown(view):
                if view.world.view3d.table_half_m is None:
                    image = None  # the world's own table is one of the meshes
                elif image is not None:  # the bare table under the meshes
                    image = np.broadcast_to(image[2, 2], image.shape)
            if image is None:
                if self.plane is not None:
                    self.plane.visible = False
                return
            image = np.ascontiguousarray(np.flipud(image))
            h, w = image.shape[:2]  # the plane keeps the frame's shape: SIZE along its longer side
            shape = (SIZE, SIZE * h / w) if w >= h else (SIZE * w / h, SIZE)
            if self.plane is None or shape != self._plane_shape:
                if self.plane is not None:
                    self.plane.remove()
                self.plane = self.client.scene.add_image(
                    "/canvas", image, *shape, format="png", receive_shadow=False
                )
                self._plane_shape = shape
            else:
                self.plane.image = image
                self.plane.visible = True

    async def _on_click(self, event) -> None:
        """On viser's event loop, so that waypoints keep the order they were clicked in."""
        self.state.submit(lambda: self._click(event), self.notify)

    def _click(self, event) -> None:
        o, d = ray(event)
        if o is None:
            return
        hit = o - o[2] / d[2] * d  # (3,) on z = 0
        width, height = self._plane_shape
        u, v = hit[0] / width + 0.5, 0.5 - hit[1] / height
        view = self.state.snapshot()
        if self.covered or view.stage != "demonstrate" or view.demo_kind != "clicks":
            return
        if not (0.0 <= u <= 1.0 and 0.0 <= v <= 1.0):
            self.notify("that click missed the image: click on the picture of the task")
            return
        self.state.edit_demo(lambda d: d.click(float(u), float(v)))

    # -- 3D scenes (the tabletop, the MuJoCo worlds) ------------------------------------------
    def show_scenes(self, view: View, step: int) -> None:
        """A world with a 3D view: the failed rollout's objects as meshes at the slider's step
        (over the image plane, as the bare table, where the view has a table of its own; a
        MuJoCo world's table and gripper are meshes too), with the counterfactual's as a
        wireframe ghost (after the diagnosis). A world without meshes: the failed rollout's
        frame at the slider's step on the plane."""
        run = view.record
        show = self._meshes_shown(view)
        if not show:
            self._show_frame(view, step)
        cf = run.diagnosis.counterfactual if show and run.diagnosis else None
        key = (id(run.rollout), id(cf), step) if show else None
        with self._lock:
            if key == self._meshes:
                return
            self._meshes = key
            nodes: dict[str, object] = {}
            if show:
                nodes = self._add_meshes(view.world.view3d, run.rollout, cf, step)
            for gone in set(self._mesh_nodes) - set(nodes):
                self._mesh_nodes[gone].remove()
            self._mesh_nodes = nodes

    def _show_frame(self, view: View, step: int) -> None:
        run = view.record
        if run is None or view.stage == "demonstrate":
            return  # the demonstration canvas is the plane's
        from dfa_viz.app import frames

        obs = run.rollout.observations  # (T + 1, H, W, 3)
        t = min(max(step, 0), len(obs) - 1)
        with self._lock:
            if self.plane is None or self._frame == (id(run.rollout), t):
                return
            self._frame = (id(run.rollout), t)
            image = frames.upscale(obs[t], frames.scale_for(obs.shape[1:], frames.CANVAS_PX))
            self.plane.image = np.ascontiguousarray(np.flipud(image))

    @staticmethod
    def _meshes_shown(view: View) -> bool:
        return (
            view.world is not None
            and view.world.view3d is not None
            and view.stage in ("feedback", "adapted")
        )

    def _add_meshes(self, view3d, failed, counterfactual, step: int) -> dict[str, object]:
        return {
            m.path: self.client.scene.add_mesh_simple(
                m.path,
                m.vertices,
                m.faces,
                color=m.rgb,
                wireframe=m.wireframe,
                wxyz=m.wxyz,
                position=m.position,
            )
            for m in placed_meshes(view3d, failed, counterfactual, step)
        }


@dataclass(frozen=True, eq=False)
class Placed:
    """One mesh as the page draws it, in scene units (the view's centre at the plane's)."""

    path: str
    vertices: np.ndarray  # float32 (V, 3), in the object's frame
    faces: np.ndarray  # uint32 (F, 3)
    rgb: tuple[int, int, int]
    wireframe: bool
    wxyz: tuple[float, float, float, float]
    position: tuple[float, float, float]


def placed_meshes(view3d, failed, counterfactual, step: int) -> list[Placed]:
    """The failed rollout's objects at `step` (solid) and those of the counterfactual that
    differ from them (wireframes). Poses only, whether the view plays actions out or not: the
    page shows steps."""
    k = SIZE / (2 * view3d.view_half_m)  # metres -> scene units: the plane spans the view
    cx, cy, cz = view3d.centre_m
    out: list[Placed] = []
    for name, traj, wireframe in (
        ("failed", failed, False),
        ("counterfactual", counterfactual, True),
    ):
        if traj is None:
            continue
        poses = view3d.poses(traj.scenes[min(step, len(traj.scenes) - 1)])
        if wireframe:  # the ghost: only what differs from the failed scene at this step
            solid = {
                q.slot: q for q in view3d.poses(failed.scenes[min(step, len(failed.scenes) - 1)])
            }
            poses = [p for p in poses if _differs(p, solid.get(p.slot))]
        for p in poses:
            mesh = view3d.mesh(p.shape)
            out.append(
                Placed(
                    f"/scenes/{name}/{p.slot}",
                    np.asarray(mesh.vertices, np.float32) * k,
                    np.asarray(mesh.faces, np.uint32),
                    GHOST_RGB if wireframe else tuple(int(255 * c) for c in p.rgba[:3]),
                    wireframe,
                    p.quat,
                    ((p.pos[0] - cx) * k, (p.pos[1] - cy) * k, (p.pos[2] - cz) * k + 0.01),
                )
            )
    return out


def ray(event) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """A click's ray (origin, direction: float (3,) each), or (None, None) for one that cannot
    meet the plane: missing, not three finite numbers each, or parallel to it."""
    try:
        o = np.asarray(event.ray_origin, dtype=float)
        d = np.asarray(event.ray_direction, dtype=float)
    except (TypeError, ValueError):
        return None, None
    if o.shape != (3,) or d.shape != (3,) or not (np.isfinite(o).all() and np.isfinite(d).all()):
        return None, None
    if abs(d[2]) < 1e-9:
        return None, None
    return o, d


def _differs(pose, other, tol_m: float = 0.005) -> bool:
    """Whether an object's pose or look differs from another's (None: it is not there)."""
    if other is None:
        return True
    moved = np.linalg.norm(np.asarray(pose.pos[:3]) - np.asarray(other.pos[:3])) > tol_m
    return moved or (pose.shape, pose.colour) != (other.shape, other.colour)
