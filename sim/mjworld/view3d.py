"""A MuJoCo world's 3D scene (World.view3d), read from the world's own model: nothing written
per task or per package.

Parts     each slot of the world (`all_slots()`: its SlotSpecs, a body's visual geoms or a
          site) is drawn as the meshes of its geoms (box, sphere, cylinder, capsule, ellipsoid
          made with trimesh; mesh geoms from the model's own vertices and faces), combined in
          the frame of the body that holds them (one part per such body: the slot's name, or
          "<slot>/<k>" where a slot's geoms lie in several bodies), or as its site's shape;
          and the end effector (`MujocoWorld.effector`: its body and every body below it, each
          finger its own part "gripper/<k>"), so that one sees where the arm is
Poses     from the scene's physics state: the world's own `restore(scene)` (and
          `before_render`, which puts Fetch's target marker at the goal) under its lock, then
          each part's body `xpos`/`xquat`, or its site's
Colours   the slot's colour concept over sim.mjworld.model.PALETTE; "as built" (and the
          effector): the colour MuJoCo draws its first visual geom with as the model builds it
          (its material's while the geom's own rgba is the default, times its texture's mean
          colour, else its own)
Actions   closed loop (one action is one control step): the poses at each step are the rollout;
          an action is drawn as the end effector's motion over its step (`grip_pos`)
View      centred on the table top's middle of the world's Workspace, framing it with MARGIN_M
          to spare; the table is one of the slots, so the view draws no table of its own
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.core import Scene
from sim.core.view3d import Look, ObjectPose, View3D

MARGIN_M = 0.15  # the views frame the workspace with this much to spare on every side
EFFECTOR = "gripper"  # the end effector's parts are "gripper/<k>"
SPHERE_COUNT = (16, 16)  # latitude, longitude segments of spheres, capsules and ellipsoids
SECTIONS = 24  # segments round a cylinder
DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)  # a geom's rgba unless its model says otherwise
TEXTURE_RGB = 1  # mujoco.mjtTextureRole.mjTEXROLE_RGB: a material's colour texture


@dataclass(frozen=True, eq=False)
class Part:
    """One rigidly posed piece of the scene: a body's visual geoms of one slot, or a site."""

    name: str
    """The pose's slot and shape name."""
    slot: str | None
    """The slot whose colour it shows (None: the end effector, always as built)."""
    body: int | None
    site: int | None
    mesh: object
    """trimesh.Trimesh, metres, in the body's (or site's) frame."""
    rgba: tuple[float, float, float, float]
    """Its colour as the model builds it."""


class MujocoView3D(View3D):
    """The 3D scene of a MujocoWorld; see the module docstring. Parts are read from the model
    when first asked for."""

    plays_actions = False  # closed loop: one action is one short control step

    def __init__(self, world) -> None:
        self._world = world  # the MujocoWorld whose model and physics state are drawn
        ws = world.workspace
        self.centre_m = (sum(ws.x_m) / 2, sum(ws.y_m) / 2, float(ws.top_m))
        self.view_half_m = max(ws.x_m[1] - ws.x_m[0], ws.y_m[1] - ws.y_m[0]) / 2 + MARGIN_M
        self._parts: tuple[Part, ...] | None = None

    def parts(self) -> tuple[Part, ...]:
        """Every part, in slot order, the end effector's last."""
        w = self._world
        with w._lock:
            if self._parts is None:
                self._parts = _read_parts(w)
            return self._parts

    def _part(self, name: str) -> Part:
        for part in self.parts():
            if part.name == name:
                return part
        raise KeyError(f"{self._world.name}: no part {name!r} in the 3D view")

    def poses(self, scene: Scene) -> list[ObjectPose]:
        import mujoco

        from sim.mjworld.model import AS_BUILT
        from sim.mjworld.world import COLOUR

        w, out = self._world, []
        with w._lock:
            parts = self.parts()
            env = w.restore(scene)
            w.before_render(env)
            _, data = w.physics(env)
            for part in parts:
                colour = AS_BUILT
                if part.slot is not None:
                    o = scene.obj(part.slot)
                    if not o.present:
                        continue
                    colour = o.value(COLOUR)
                if part.body is not None:
                    pos, quat = data.xpos[part.body], data.xquat[part.body]
                else:
                    pos, quat = data.site_xpos[part.site], np.empty(4)
                    mujoco.mju_mat2Quat(quat, data.site_xmat[part.site])
                out.append(
                    ObjectPose(
                        part.name,
                        part.name,
                        colour,
                        _rgba(part, colour),
                        tuple(float(v) for v in pos),
                        tuple(float(v) for v in quat),
                    )
                )
        return out

    def mesh(self, shape: str):
        return self._part(shape).mesh

    def look(self, shape: str, colour: str) -> Look:
        return Look(_rgba(self._part(shape), colour))

    def arrow(self, scene: Scene, action: Sequence[float], after: Scene):
        """The end effector's motion over the step: from where it is in `scene` to where it is
        in `after`."""
        w = self._world
        with w._lock:
            a = np.array(w.grip_pos(w.restore(scene)), float)
            b = np.array(w.grip_pos(w.restore(after)), float)
        return tuple(float(v) for v in a), tuple(float(v) for v in b - a)


def _rgba(part: Part, colour: str) -> tuple[float, float, float, float]:
    from sim.mjworld.model import PALETTE

    if colour in PALETTE:
        return (*PALETTE[colour], 1.0)
    return part.rgba


def _read_parts(world) -> tuple[Part, ...]:
    """The parts of `world`'s slots and end effector, from its compiled model (the slots' looks
    as built: the model itself may be painted for some scene)."""
    from sim.mjworld.model import body_geoms

    model, _ = world.physics(world._open())
    parts: list[Part] = []
    for spec in world.all_slots():
        looks = world._looks[spec.name]
        built = [_shown(model, looks.rgba[i], m) for i, m in enumerate(looks.matids)]
        parts += _body_parts(model, spec.name, spec.name, looks.geoms, built)
        for j, s in enumerate(looks.sites):
            mesh = _shape(model, model.site_type[s], model.site_size[s], None)
            if mesh is not None:
                rgba = looks.rgba[len(looks.geoms) + j]
                parts.append(Part(spec.name, spec.name, None, s, mesh, _tuple(rgba)))
    if world.effector is not None:
        geoms = body_geoms(model, world.effector, world.drawn_groups)
        built = [_shown(model, model.geom_rgba[g], model.geom_matid[g]) for g in geoms]
        parts += _body_parts(model, EFFECTOR, None, geoms, built, always_numbered=True)
    return tuple(parts)


def _shown(model, rgba, matid: int) -> np.ndarray:
    """The rgba MuJoCo draws a geom with: its material's while the geom's own is the default
    one (a textured material's times its texture's mean colour), else its own."""
    if matid >= 0 and np.allclose(rgba, DEFAULT_RGBA):
        out = np.array(model.mat_rgba[matid], float)
        out[:3] *= _texture_mean(model, int(model.mat_texid[matid][TEXTURE_RGB]))
        return out
    return np.array(rgba, float)


def _texture_mean(model, tex: int) -> np.ndarray:
    """float (3,) in [0, 1]: the mean colour of texture `tex` (ones for none)."""
    if tex < 0:
        return np.ones(3)
    n = model.tex_height[tex] * model.tex_width[tex] * model.tex_nchannel[tex]
    pixels = np.asarray(model.tex_data[model.tex_adr[tex] : model.tex_adr[tex] + n], float)
    pixels = pixels.reshape(-1, model.tex_nchannel[tex])
    if pixels.shape[1] < 3:
        return np.full(3, pixels[:, 0].mean() / 255)
    return pixels[:, :3].mean(axis=0) / 255


def _body_parts(
    model, name: str, slot: str | None, geoms, built, *, always_numbered: bool = False
) -> list[Part]:
    """One part per body holding some of `geoms`, its geoms' meshes combined in its frame;
    named `name` (a single body) or "<name>/<k>"."""
    import trimesh

    bodies: dict[int, list[int]] = {}
    for k, g in enumerate(geoms):
        bodies.setdefault(int(model.geom_bodyid[g]), []).append(k)
    out = []
    for n, (body, ks) in enumerate(bodies.items()):
        meshes = []
        for k in ks:
            g = geoms[k]
            mesh = _shape(model, model.geom_type[g], model.geom_size[g], int(model.geom_dataid[g]))
            if mesh is not None:
                mesh.apply_transform(_pose_matrix(model.geom_pos[g], model.geom_quat[g]))
                meshes.append(mesh)
        if not meshes:
            continue
        part_name = f"{name}/{n}" if always_numbered or len(bodies) > 1 else name
        mesh = trimesh.util.concatenate(meshes)
        out.append(Part(part_name, slot, body, None, mesh, _tuple(built[ks[0]])))
    return out


def _shape(model, kind, size, mesh_id: int | None):
    """A geom's (or site's) shape in its own frame, as MuJoCo sizes it (half sizes, radii,
    half lengths); None for those not drawn as a solid here (planes, height fields)."""
    import mujoco
    import trimesh

    T = mujoco.mjtGeom
    kind, size = int(kind), np.asarray(size, float)
    if kind == T.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * size[:3])
    if kind == T.mjGEOM_SPHERE:
        return trimesh.creation.uv_sphere(radius=size[0], count=SPHERE_COUNT)
    if kind == T.mjGEOM_ELLIPSOID:
        mesh = trimesh.creation.uv_sphere(radius=1.0, count=SPHERE_COUNT)
        mesh.apply_scale(size[:3])
        return mesh
    if kind == T.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=SECTIONS)
    if kind == T.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=SPHERE_COUNT)
    if kind == T.mjGEOM_MESH and mesh_id is not None and mesh_id >= 0:
        v0, nv = model.mesh_vertadr[mesh_id], model.mesh_vertnum[mesh_id]
        f0, nf = model.mesh_faceadr[mesh_id], model.mesh_facenum[mesh_id]
        vertices = np.array(model.mesh_vert[v0 : v0 + nv], float)
        faces = np.array(model.mesh_face[f0 : f0 + nf], np.int64)
        return trimesh.Trimesh(vertices, faces, process=False)
    return None


def _pose_matrix(pos, quat_wxyz) -> np.ndarray:
    """float (4, 4): the rigid transform of a position and a quaternion (w, x, y, z)."""
    import trimesh

    m = trimesh.transformations.quaternion_matrix(np.asarray(quat_wxyz, float))
    m[:3, 3] = pos
    return m


def _tuple(rgba) -> tuple[float, float, float, float]:
    return tuple(float(c) for c in np.asarray(rgba, float)[:4])
