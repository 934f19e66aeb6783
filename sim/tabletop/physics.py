"""The pick-and-place primitive, simulated: pick, carry, lower until contact, release, settle.

The gripper is a mocap body. Picking welds the object under the pick point to it (a MuJoCo weld
equality, so the carry is a constrained motion of a free body with gravity and contacts); the
gripper lifts, moves by (place - pick), lowers until the object touches something, lets go, and
MuJoCo simulates everything settling.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported: headless rendering

from dataclasses import replace

import mujoco
import numpy as np

from sim.core import Obj, Scene
from sim.core.view3d import Frames
from sim.tabletop import meshes as M
from sim.tabletop.model import SLOTS, TIMESTEP_S, Table
from sim.tabletop.tasks import VIEW_HALF_M

CARRY_Z_M = 0.12  # the gripper carries objects with their origin this high above the table
LIFT_SPEED = 1.0  # m/s
MOVE_SPEED = 2.0  # m/s
LOWER_SPEED = 0.5  # m/s
SETTLE_MAX_S = 1.0
STILL_SPEED = 0.03  # m/s or rad/s: below this every object counts as at rest
POSE_DECIMALS = 6  # settled poses are rounded to a micrometre so scenes stay compact


def _world_hull(obj: Obj) -> np.ndarray:
    """The object's top-down convex footprint in table coordinates: (N, 2)."""
    hull = M.footprint_hull(obj.value("shape"))
    pts = np.column_stack([hull, np.zeros(len(hull))])  # (N, 3)
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(obj.pos[3:7], float))
    return (pts @ mat.reshape(3, 3).T)[:, :2] + np.asarray(obj.pos[:2])


def _inside_convex(poly: np.ndarray, xy: np.ndarray) -> bool:
    edge = np.roll(poly, -1, axis=0) - poly  # (N, 2)
    rel = xy[None, :] - poly
    cross = edge[:, 0] * rel[:, 1] - edge[:, 1] * rel[:, 0]
    return bool(np.all(cross >= 0) or np.all(cross <= 0))


def object_at(scene: Scene, xy) -> str | None:
    """The slot the gripper takes at table point xy: the topmost present object whose convex
    footprint contains it (a suction cup the size of the object), or None."""
    xy = np.asarray(xy, float)
    best, best_top = None, -np.inf
    for o in scene.objects:
        if not o.present or not _inside_convex(_world_hull(o), xy):
            continue
        top = o.pos[2] + float(M.shape_mesh(o.value("shape")).bounds[1, 2])
        if top > best_top:
            best, best_top = o.slot, top
    return best


class PickPlace:
    """Executes the primitive on the shared Table (its data is overwritten every call)."""

    def __init__(self, table: Table) -> None:
        self.table = table
        m = table.model
        self._body_slot = {table.slots[s].body: s for s in SLOTS}
        self._geom_body = m.geom_bodyid.copy()

    # -- helpers ------------------------------------------------------------------------------
    def _start(self, scene: Scene) -> None:
        m, d = self.table.model, self.table.data
        mujoco.mj_resetData(m, d)
        self.table.load(scene)
        mujoco.mj_forward(m, d)

    def _touching(self, body: int) -> bool:
        d = self.table.data
        if d.ncon == 0:
            return False
        geoms = d.contact.geom[: d.ncon]  # (ncon, 2)
        hit = (self._geom_body[geoms] == body).any(axis=1)
        return bool(np.any(hit & (d.contact.dist[: d.ncon] < 1e-3)))

    def _present(self, scene: Scene) -> list[str]:
        return [o.slot for o in scene.objects if o.present]

    def _still(self, slots: list[str]) -> bool:
        d = self.table.data
        return all(
            np.max(np.abs(d.qvel[self.table.slots[s].dof : self.table.slots[s].dof + 6]))
            < STILL_SPEED
            for s in slots
        )

    # -- the primitive ------------------------------------------------------------------------
    def run(self, scene: Scene, action: np.ndarray, *, every: int = 0) -> tuple[Scene, Frames]:
        """Simulate one pick-and-place from `scene`. action: (pick_x, pick_y, place_x, place_y)
        in metres, clipped to the camera's view of the table.

        every: record the poses every this many physics steps (0: only start and end).
        Returns the scene after settling (agent = (1.0,)) and the recorded frames.
        """
        a = np.clip(np.asarray(action, float).reshape(4), -VIEW_HALF_M, VIEW_HALF_M)
        d = self.table.data
        present = self._present(scene)
        picked = object_at(scene, a[:2])
        rec: list[tuple[float, np.ndarray, np.ndarray]] = []
        bodies = [self.table.slots[s].body for s in present]

        def record() -> None:
            rec.append((float(d.time), d.xpos[bodies].copy(), d.xquat[bodies].copy()))

        self._start(scene)
        record()
        if picked is not None:
            self._carry(picked, a, present, every, record)
        self._settle(present, every, record)
        if not rec or rec[-1][0] != d.time:
            record()
        objs = []
        for o in scene.objects:
            if o.present:
                adr = self.table.slots[o.slot].qpos
                q = d.qpos[adr : adr + 7].copy()
                q[3:] /= np.linalg.norm(q[3:])
                pos = tuple(float(v) for v in np.round(q, POSE_DECIMALS))
                o = replace(o, pos=pos)
            objs.append(o)
        frames = Frames(
            tuple(present),
            np.array([r[0] for r in rec]),
            np.stack([r[1] for r in rec]).reshape(len(rec), len(present), 3),
            np.stack([r[2] for r in rec]).reshape(len(rec), len(present), 4),
            picked,
        )
        return Scene(
            scene.world, tuple(objs), (scene.agent[0] + 1.0 if scene.agent else 1.0,)
        ), frames

    def _carry(self, slot: str, a: np.ndarray, present: list[str], every: int, record) -> None:
        m, d = self.table.model, self.table.data
        idx = self.table.slots[slot]
        mocap = self.table.gripper_mocap
        start = d.xpos[idx.body].copy()
        d.mocap_pos[mocap] = start
        d.mocap_quat[mocap] = d.xquat[idx.body]
        m.eq_data[idx.weld, :] = 0.0
        m.eq_data[idx.weld, 6] = 1.0  # relative pose: identity
        m.eq_data[idx.weld, 10] = 1.0  # torque scale
        d.eq_active[idx.weld] = 1
        target = start + np.array([a[2] - a[0], a[3] - a[1], 0.0])
        lift = np.array([start[0], start[1], CARRY_Z_M])
        over = np.array([target[0], target[1], CARRY_Z_M])
        n = 0
        for p0, p1, speed in ((start, lift, LIFT_SPEED), (lift, over, MOVE_SPEED)):
            steps = max(1, int(np.ceil(np.linalg.norm(p1 - p0) / speed / TIMESTEP_S)))
            for i in range(1, steps + 1):
                d.mocap_pos[mocap] = p0 + (p1 - p0) * i / steps
                mujoco.mj_step(m, d)
                n += 1
                if every and n % every == 0:
                    record()
        # lower until the carried object touches something (or the gripper reaches the table)
        z = CARRY_Z_M
        dz = LOWER_SPEED * TIMESTEP_S
        while z > 0.0 and not self._touching(idx.body):
            z -= dz
            d.mocap_pos[mocap] = (over[0], over[1], z)
            mujoco.mj_step(m, d)
            n += 1
            if every and n % every == 0:
                record()
        d.eq_active[idx.weld] = 0

    def _settle(self, present: list[str], every: int, record) -> None:
        m, d = self.table.model, self.table.data
        steps = int(SETTLE_MAX_S / TIMESTEP_S)
        still = 0
        for n in range(1, steps + 1):
            mujoco.mj_step(m, d)
            if every and n % every == 0:
                record()
            if n % 10 == 0:
                still = still + 1 if self._still(present) else 0
                if still >= 3:
                    break
