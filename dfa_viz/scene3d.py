"""A world's 3D scene for the recording (World.view3d): each object's mesh once, its pose over
time.

Layout under `scene3d/<rollout>/` (rollout: failed, demonstration, counterfactual, finetuned):
    table           static Boxes3D, the table top (views with a table of their own: the
                    tabletop's; a MuJoCo world's table is one of its slots)
    view            static LineStrips3D, the square of the table the top-down camera sees
                    (the tabletop's 80x80 one; with the table)
    <slot>          static Mesh3D in the object's body frame (metres), and a Transform3D per
                    row: on the `step` timeline the pose at each step of the rollout; for a
                    view that plays actions out (the tabletop's), also on the `sim_time`
                    timeline (seconds of simulated time) the carry and the settling of each
                    pick-and-place, one row per 20 ms. A MuJoCo world's slots and its gripper
                    ("gripper/<k>", each finger its own) are posed at each step only: one
                    action is one short control step
    action          Arrows3D of each action, on the `step` timeline (View3D.arrow: the
                    tabletop's from the pick point to the place point, a MuJoCo world's the
                    gripper's motion over the step)
    trail/<slot>    LineStrips3D: the path of each object a pick-and-place moved, from the
                    step after it on (the carry, seen without leaving the `step` timeline)

The meshes, looks and poses come from the world's View3D (the tabletop's: the same geometry
MuJoCo simulates and renders; a MuJoCo world's: its own model's geoms; the web page reuses it
too).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from sim.core import Scene, Trajectory, World
from sim.core.view3d import View3D

ROOT = "scene3d"
VIEWS = ("failed", "counterfactual")  # the two rollouts the user compares in 3D
FRAME_EVERY = 5  # physics steps between recorded poses (5 x 4 ms = 20 ms)
ARROW_RGB = (250, 120, 20)  # orange: seen against the grey table and the floor
ARROW_RADIUS_M = 0.008  # the action arrow's, at most a fifth of its length
EYE_HALVES = (0.0, -1.875, 1.625)  # the 3D views' camera from the view's centre, in view halves
# (the tabletop's, view_half_m 0.4: 0.75 m in front of the table's centre, 0.65 m above it)
MOVED_M = 0.01  # objects that move more than this during a pick-and-place leave a trail


def views(view: View3D) -> list:
    """Blueprint views: the failed rollout and the counterfactual in 3D, seen obliquely from
    in front of the view's centre, the whole view in sight."""
    centre = np.asarray(view.centre_m, float)
    eye_m = centre + np.asarray(EYE_HALVES) * view.view_half_m
    eye = rrb.EyeControls3D(
        kind="Orbital",
        position=tuple(float(v) for v in eye_m),
        look_target=tuple(float(v) for v in centre),
        eye_up=(0.0, 0.0, 1.0),
    )
    return [
        rrb.Spatial3DView(origin=f"{ROOT}/{name}", name=f"{name} (3D)", eye_controls=eye)
        for name in VIEWS
    ]


@lru_cache(maxsize=64)
def _mesh(view: View3D, shape: str, colour: str) -> rr.Mesh3D:
    """The display mesh of `shape` in `colour`, flat shaded (every face its own corners)."""
    mesh = view.mesh(shape)
    look = view.look(shape, colour)
    corners = mesh.vertices[mesh.faces].reshape(-1, 3).astype(np.float32)  # (3F, 3)
    normals = np.repeat(mesh.face_normals, 3, axis=0).astype(np.float32)  # (3F, 3)
    triangles = np.arange(len(corners), dtype=np.uint32).reshape(-1, 3)  # (F, 3)
    if look.texture is None:
        return rr.Mesh3D(
            vertex_positions=corners,
            triangle_indices=triangles,
            vertex_normals=normals,
            albedo_factor=look.rgba,
        )
    # a texture, projected from above (one tile per tile_m metres); the image holds 3x3 tiles
    # so that no texture wrap mode is needed for objects under 3 tiles across
    tiles = np.tile(look.texture, (3, 3, 1))  # (3 P, 3 P, 3) uint8
    uv = (corners[:, :2] / look.tile_m + 0.5 + 1.0) / 3.0  # (3F, 2) in [0, 1]
    return rr.Mesh3D(
        vertex_positions=corners,
        triangle_indices=triangles,
        vertex_normals=normals,
        vertex_texcoords=uv.astype(np.float32),
        albedo_texture=tiles,
    )


def _static_table(rec: rr.RecordingStream, view: View3D, base: str) -> None:
    """The table top and the square its top-down camera sees (views with a table)."""
    if view.table_half_m is None:
        return
    cx, cy, cz = (float(c) for c in view.centre_m)
    half = (view.table_half_m, view.table_half_m, view.table_thickness_m / 2)
    rec.log(
        f"{base}/table",
        rr.Boxes3D(
            half_sizes=[half],
            centers=[(cx, cy, cz - view.table_thickness_m / 2)],
            colors=[view.table_rgb],
            fill_mode="solid",
        ),
        static=True,
    )
    v, z = view.view_half_m, cz + 0.001
    corners = [(-v, -v), (v, -v), (v, v), (-v, v), (-v, -v)]
    square = [(cx + x, cy + y, z) for x, y in corners]
    rec.log(
        f"{base}/view",
        rr.LineStrips3D([square], colors=[(255, 255, 255)], radii=0.002),
        static=True,
    )


def _transform(pos, quat_wxyz) -> rr.Transform3D:
    w, x, y, z = (float(q) for q in quat_wxyz)
    return rr.Transform3D(
        translation=[float(p) for p in pos[:3]], quaternion=rr.Quaternion(xyzw=[x, y, z, w])
    )


def _log_step_poses(
    rec: rr.RecordingStream, view: View3D, base: str, scene: Scene, step: int
) -> None:
    rec.reset_time()
    rec.set_time("step", sequence=step)
    for p in view.poses(scene):
        rec.log(f"{base}/{p.slot}", _transform(p.pos, p.quat))


def _log_arrow(rec: rr.RecordingStream, base: str, origin, vector) -> None:
    length = float(np.linalg.norm(vector))
    rec.log(
        f"{base}/action",
        rr.Arrows3D(
            origins=[origin],
            vectors=[vector],
            colors=[ARROW_RGB],
            radii=min(ARROW_RADIUS_M, max(length / 5, 1e-4)),
        ),
    )


def _log_trails(rec: rr.RecordingStream, base: str, frames, step: int) -> None:
    """The path of every object the pick-and-place moved, shown from `step` on: the carry
    seen on the `step` timeline (the `sim_time` timeline plays it)."""
    rec.reset_time()
    rec.set_time("step", sequence=step)
    for k, slot in enumerate(frames.slots):
        path = np.asarray(frames.pos[:, k, :3], np.float64)  # (F, 3)
        if len(path) > 1 and np.linalg.norm(path[-1] - path[0]) > MOVED_M:
            rec.log(
                f"{base}/trail/{slot}",
                rr.LineStrips3D([path], colors=[ARROW_RGB], radii=0.003),
            )


def log_rollout(rec: rr.RecordingStream, world: World, name: str, traj: Trajectory) -> None:
    """Log one rollout under scene3d/<name>: meshes once, poses over time.

    world: a world with a 3D view. A view that plays actions out (the tabletop's) plays each
    action out again, with poses every 20 ms (the simulation is deterministic, so it ends where
    traj does); a closed-loop one (the MuJoCo worlds') is posed at each step.
    traj: scenes (T+1,), actions (T, A) as the world takes them.
    """
    view = world.view3d
    assert view is not None, f"{world.name} has no 3D view"
    base = f"{ROOT}/{name}"
    _static_table(rec, view, base)
    for p in view.poses(traj.scenes[0]):
        rec.log(f"{base}/{p.slot}", _mesh(view, p.shape, p.colour), static=True)
    actions = np.asarray(traj.actions, np.float64).reshape(traj.horizon, -1)  # (T, A)
    t0_s = 0.0
    for t in range(traj.horizon + 1):
        _log_step_poses(rec, view, base, traj.scenes[t], t)
        if t == traj.horizon or world.done(traj.scenes[t]):
            continue
        a = actions[t]
        origin, vector = view.arrow(traj.scenes[t], a, traj.scenes[t + 1])
        _log_arrow(rec, base, origin, vector)
        if not view.plays_actions:
            continue
        frames = view.frames(traj.scenes[t], a, every=FRAME_EVERY)
        _log_trails(rec, base, frames, t + 1)
        rec.reset_time()
        for f, time_s in enumerate(frames.times_s):
            rec.set_time("sim_time", duration=t0_s + float(time_s))
            for k, slot in enumerate(frames.slots):
                rec.log(f"{base}/{slot}", _transform(frames.pos[f, k], frames.quat[f, k]))
        t0_s += float(frames.times_s[-1]) if len(frames.times_s) else 0.0
    rec.reset_time()
