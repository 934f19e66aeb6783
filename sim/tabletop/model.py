"""The one MuJoCo model of the table, built once with MjSpec, and scenes written into it in place.

Each of the four slots is a free body with a small pool of collision geoms, rewritten for its
current shape from a library of every shape's compiled collision geoms, and a welded child body
holding one display mesh per shape (shown or hidden through its geom group). An appearance is a
material (82 of them: plain colours and textures). Changing a scene's shape, colour, presence or
pose writes model and data fields; nothing is recompiled.
"""

from __future__ import annotations

import hashlib
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.core import Scene
from sim.tabletop import colours as C
from sim.tabletop import meshes as M
from sim.tabletop import textures as T
from sim.tabletop.catalogue import SHAPES
from sim.tabletop.pose import TABLE_HALF_M, TABLE_THICKNESS_M
from sim.tabletop.tasks import VIEW_HALF_M

SLOTS = ("object", "goal", "distractor0", "distractor1")
OBJECT_MASS_KG = 0.1
GROUP_SHOWN, GROUP_HIDDEN, GROUP_COLLISION = 0, 1, 3
AMBIENT = 0.6  # headlight ambient + diffuse = 1: a face seen head-on shows its exact colour
TIMESTEP_S = 0.004
PARK_M = 5.0  # absent objects wait this far off the table, without contacts


@dataclass(frozen=True)
class SlotIndex:
    """Where one slot lives in the compiled model."""

    body: int
    qpos: int  # address of the free joint's 7 qpos (x, y, z, qw, qx, qy, qz)
    dof: int  # address of its 6 dofs
    visual: np.ndarray  # (n_shapes,) int: the display mesh geom of each shape
    pool: np.ndarray  # (POOL,) int: the collision geoms, configured for the current shape
    weld: int  # the equality that welds this body to the gripper


@dataclass(frozen=True)
class CollisionSet:
    """A shape's compiled collision geoms, copied into a slot's pool when it takes the shape.

    Arrays are (n, ...) with n <= POOL: MuJoCo geom type, mesh id (-1 for primitives), size,
    pos, quat, aabb (centre, half extents in the geom frame) and bounding radius.
    """

    type: np.ndarray  # (n,) int
    dataid: np.ndarray  # (n,) int
    size: np.ndarray  # (n, 3)
    pos: np.ndarray  # (n, 3)
    quat: np.ndarray  # (n, 4)
    aabb: np.ndarray  # (n, 6)
    rbound: np.ndarray  # (n,)


POOL = max(max(1, len(M.collision_prims(n))) for n in SHAPES)
LIBRARY_Z_M = -50.0  # the static body holding every shape's collision geoms, out of reach


def _add_assets(spec: mujoco.MjSpec) -> None:
    for name in C.TEXTURES:
        img = T.texture(name)  # (TEX_PX, TEX_PX, 3) uint8
        tex = spec.add_texture(
            name=f"tex:{name}",
            type=mujoco.mjtTexture.mjTEXTURE_2D,
            width=T.TEX_PX,
            height=T.TEX_PX,
            nchannel=3,
        )
        tex.data = img.tobytes()
    for name in C.ALL_COLOURS:
        rgb = C.PLAIN_RGB.get(name, (255, 255, 255))
        mat = spec.add_material(
            name=f"mat:{name}",
            rgba=[c / 255 for c in rgb] + [1.0],
            specular=0.0,
            shininess=0.0,
            reflectance=0.0,
        )
        if not C.is_plain(name):
            mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tex:{name}"
    spec.add_material(
        name="mat:table", rgba=[c / 255 for c in C.TABLE_RGB] + [1.0], specular=0.0, shininess=0.0
    )
    for name in SHAPES:
        mesh = M.shape_mesh(name)
        # every face gets its own corners and normal: flat shading, so that a face seen
        # head-on shows exactly its colour
        corners = mesh.vertices[mesh.faces].reshape(-1, 3)  # (3F, 3)
        normals = np.repeat(mesh.face_normals, 3, axis=0)  # (3F, 3)
        uv = corners[:, :2] / T.TEX_M + 0.5  # planar projection from above
        spec.add_mesh(
            name=f"mesh:{name}",
            uservert=corners.ravel().tolist(),
            userface=list(range(len(corners))),
            usertexcoord=uv.ravel().tolist(),
            usernormal=normals.ravel().tolist(),
            inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL,
        )


def _add_collision_geoms(body, name: str, prefix: str) -> None:
    """The collision geoms of one shape: its primitives, or its display mesh (convex hull)."""
    prims = M.collision_prims(name)
    if not prims:
        body.add_geom(
            name=f"{prefix}0",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"mesh:{name}",
            group=GROUP_COLLISION,
        )
    for i, p in enumerate(prims):
        body.add_geom(
            name=f"{prefix}{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX if p.kind == "box" else mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=list(p.size),
            pos=list(p.pos),
            quat=list(p.quat),
            group=GROUP_COLLISION,
        )


def _add_slot(spec: mujoco.MjSpec, slot: str, k: int) -> None:
    body = spec.worldbody.add_body(name=slot, pos=[PARK_M + k, PARK_M, 0.0])
    body.add_freejoint(name=f"{slot}:free")
    body.explicitinertial = True
    com, diag = M.inertia("block", OBJECT_MASS_KG)
    body.mass, body.ipos, body.inertia = OBJECT_MASS_KG, com.tolist(), diag.tolist()
    for i in range(POOL):  # compiled collidable, so that the body joins the broad phase
        body.add_geom(
            name=f"{slot}:pool{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.01, 0.01, 0.01],
            pos=[0.0, 0.0, 0.01],
            group=GROUP_COLLISION,
        )
    # the display meshes ride on a welded child body that never collides
    look = body.add_body(name=f"{slot}:look")
    look.explicitinertial = True
    look.mass, look.inertia = 1e-9, [1e-12] * 3
    for name in SHAPES:
        look.add_geom(
            name=f"{slot}:{name}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"mesh:{name}",
            material="mat:red",
            group=GROUP_HIDDEN,
            contype=0,
            conaffinity=0,
        )


def _add_library(spec: mujoco.MjSpec) -> None:
    """A static body with every shape's collision geoms: MuJoCo compiles them (mesh hulls,
    mesh frame offsets, bounds) once, and slots copy them into their pools."""
    lib = spec.worldbody.add_body(name="library", pos=[0.0, 0.0, LIBRARY_Z_M])
    for name in SHAPES:
        _add_collision_geoms(lib, name, f"lib:{name}:")


def build_spec() -> mujoco.MjSpec:
    """The whole table: assets, table, top camera, gripper, four slot bodies and their welds."""
    spec = mujoco.MjSpec()
    spec.modelname = "tabletop"
    spec.option.timestep = TIMESTEP_S
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    # pools are rewritten at run time, so the compiled per-body BVHs would be stale
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
    # objects at rest (the goal and distractors during a carry) sleep until something hits them
    if not hasattr(mujoco.mjtEnableBit, "mjENBL_SLEEP"):  # MuJoCo before 3.4
        spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_MULTICCD
    if hasattr(mujoco.mjtEnableBit, "mjENBL_SLEEP"):
        spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_SLEEP
    spec.visual.headlight.ambient = [AMBIENT] * 3
    spec.visual.headlight.diffuse = [1.0 - AMBIENT] * 3
    spec.visual.headlight.specular = [0.0] * 3
    spec.visual.map.znear = 0.01
    spec.stat.extent = 1.0
    spec.stat.center = [0.0, 0.0, 0.0]
    _add_assets(spec)
    wb = spec.worldbody
    wb.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[TABLE_HALF_M, TABLE_HALF_M, TABLE_THICKNESS_M / 2],
        pos=[0.0, 0.0, -TABLE_THICKNESS_M / 2],
        material="mat:table",
        group=GROUP_SHOWN,
    )
    top = wb.add_camera(name="top", pos=[0.0, 0.0, 1.0], fovy=2 * VIEW_HALF_M)
    if hasattr(top, "proj"):  # MuJoCo 3.4 on
        top.proj = mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC
    else:
        top.orthographic = True
    wb.add_body(name="gripper", mocap=True, pos=[0.0, 0.0, 0.5])
    _add_library(spec)
    for k, slot in enumerate(SLOTS):
        _add_slot(spec, slot, k)
        spec.add_equality(
            name=f"{slot}:weld",
            type=mujoco.mjtEq.mjEQ_WELD,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=slot,
            name2="gripper",
            active=False,
            solref=[0.01, 1.0],
        )
    return spec


def _digest(model: mujoco.MjModel) -> str:
    """16 hex digits of a compiled model's bytes and MuJoCo's version."""
    mjb = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, mjb)
    return hashlib.sha256(mujoco.__version__.encode() + mjb.tobytes()).hexdigest()[:16]


class Table:
    """The compiled model and its data, with a scene written in place by `load`."""

    def __init__(self) -> None:
        self.model: mujoco.MjModel = build_spec().compile()
        self.digest = _digest(self.model)  # as compiled: `load` and the camera change it later
        self.data = mujoco.MjData(self.model)
        m = self.model

        def gid(name: str) -> int:
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)

        self.material = {
            n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_MATERIAL, f"mat:{n}") for n in C.ALL_COLOURS
        }
        self.shape_index = {n: i for i, n in enumerate(SHAPES)}
        self.collision: list[CollisionSet] = []
        for name in SHAPES:
            ids = np.array(
                [gid(f"lib:{name}:{i}") for i in range(max(1, len(M.collision_prims(name))))]
            )
            self.collision.append(
                CollisionSet(
                    m.geom_type[ids].copy(),
                    m.geom_dataid[ids].copy(),
                    m.geom_size[ids].copy(),
                    m.geom_pos[ids].copy(),
                    m.geom_quat[ids].copy(),
                    m.geom_aabb[ids].copy(),
                    m.geom_rbound[ids].copy(),
                )
            )
            m.geom_contype[ids] = 0
            m.geom_conaffinity[ids] = 0
        self.slots: dict[str, SlotIndex] = {}
        for slot in SLOTS:
            body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, slot)
            jnt = m.body_jntadr[body]
            self.slots[slot] = SlotIndex(
                body,
                int(m.jnt_qposadr[jnt]),
                int(m.jnt_dofadr[jnt]),
                np.array([gid(f"{slot}:{n}") for n in SHAPES]),
                np.array([gid(f"{slot}:pool{i}") for i in range(POOL)]),
                mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, f"{slot}:weld"),
            )
            self._clear_pool(self.slots[slot].pool)
        gripper = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "gripper")
        self.gripper_mocap = int(m.body_mocapid[gripper])
        self._inertia = [M.inertia(n, OBJECT_MASS_KG) for n in SHAPES]
        # what is written now, per slot: (shape index, material id, present)
        self._state: dict[str, tuple[int, int, bool]] = {s: (-1, -1, False) for s in SLOTS}

    def _clear_pool(self, pool: np.ndarray) -> None:
        m = self.model
        m.geom_type[pool] = mujoco.mjtGeom.mjGEOM_BOX
        m.geom_dataid[pool] = -1
        m.geom_size[pool] = 1e-4
        m.geom_pos[pool] = 0.0
        m.geom_quat[pool] = (1.0, 0.0, 0.0, 0.0)
        m.geom_aabb[pool] = (0.0, 0.0, 0.0, 1e-4, 1e-4, 1e-4)
        m.geom_rbound[pool] = 2e-4
        m.geom_contype[pool] = 0
        m.geom_conaffinity[pool] = 0
        # the pool's compiled frames were trivial; MuJoCo must not take the shortcut for them
        m.geom_sameframe[pool] = int(mujoco.mjtSameFrame.mjSAMEFRAME_NONE)

    def _fill_pool(self, pool: np.ndarray, shape: int) -> None:
        m, c = self.model, self.collision[shape]
        ids = pool[: len(c.type)]
        m.geom_type[ids] = c.type
        m.geom_dataid[ids] = c.dataid
        m.geom_size[ids] = c.size
        m.geom_pos[ids] = c.pos
        m.geom_quat[ids] = c.quat
        m.geom_aabb[ids] = c.aabb
        m.geom_rbound[ids] = c.rbound
        m.geom_contype[ids] = 1
        m.geom_conaffinity[ids] = 1

    def load(self, scene: Scene) -> None:
        """Write the scene's shapes, appearances, presence and poses into model and data.

        Only qpos is set in data; call mj_kinematics (render) or mj_forward (physics) after.
        """
        m, d = self.model, self.data
        for k, slot in enumerate(SLOTS):
            o = scene.obj(slot)
            idx = self.slots[slot]
            shape = self.shape_index[o.value("shape")]
            state = (shape, self.material[o.value("colour")], o.present)
            old = self._state[slot]
            if state != old:
                if old[0] >= 0:
                    m.geom_group[idx.visual[old[0]]] = GROUP_HIDDEN
                self._clear_pool(idx.pool)
                if o.present:
                    g = idx.visual[shape]
                    m.geom_group[g] = GROUP_SHOWN
                    m.geom_matid[g] = state[1]
                    self._fill_pool(idx.pool, shape)
                com, diag = self._inertia[shape]
                m.body_ipos[idx.body] = com
                m.body_inertia[idx.body] = diag
                self._state[slot] = state
            q = d.qpos[idx.qpos : idx.qpos + 7]
            if o.present:
                q[:] = o.pos
            else:
                q[:] = (PARK_M + k, PARK_M, 0.0, 1.0, 0.0, 0.0, 0.0)
