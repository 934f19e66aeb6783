"""The MuJoCo worlds' 3D view (sim.mjworld.view3d) on gymnasium-robotics' FetchPickAndPlace:
poses read back independently from a scene's physics state, meshes the size of the model's
geoms, colours from the scene's looks, the action as the gripper's motion."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import sim
from sim.mjworld import world as MW
from sim.mjworld.model import PALETTE
from sim.mjworld.view3d import EFFECTOR, MujocoView3D

PICK = "fetch:FetchPickAndPlace-v4"


@pytest.fixture(scope="module")
def world():
    return sim.get_world(PICK)


@pytest.fixture(scope="module")
def demo(world):
    demo = world.demonstrate(world.train_task(0))
    assert demo.success
    return demo


def _physics(world, scene) -> mujoco.MjData:
    """A fresh MjData of the world's model holding `scene`'s physics state (not the world's
    own restore)."""
    model, _ = world.physics(world._open())
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, np.asarray(scene.agent[world.head :]), MW.STATE_BITS)
    mujoco.mj_forward(model, data)
    return data


def _lifted(world, demo) -> int:
    """The first step at which the demonstration holds the object 5 cm over where it began."""
    z = [s.obj("object").pos[2] for s in demo.scenes]
    return next(t for t in range(len(z)) if z[t] > z[0] + 0.05)


def test_the_world_declares_a_closed_loop_view(world):
    view = world.view3d
    assert isinstance(view, MujocoView3D) and not view.plays_actions
    assert view.table_half_m is None  # Fetch's table is a slot, drawn as one
    ws = world.workspace
    assert ws.x_m[0] < view.centre_m[0] < ws.x_m[1] and ws.y_m[0] < view.centre_m[1] < ws.y_m[1]
    assert view.centre_m[2] == ws.top_m


def test_poses_are_the_physics_state_after_steps_of_the_expert(world, demo):
    view, model = world.view3d, world.physics(world._open())[0]
    t = _lifted(world, demo)
    for scene in (demo.scenes[0], demo.scenes[t], demo.scenes[-1]):
        data = _physics(world, scene)
        poses = {p.slot: p for p in view.poses(scene)}
        assert set(poses) == {"object", "target", "table", *(f"{EFFECTOR}/{k}" for k in range(3))}
        for slot, body in (("object", "object0"), ("table", "table0")):
            assert np.allclose(poses[slot].pos, data.body(body).xpos, atol=1e-9)
            assert np.allclose(poses[slot].quat, data.body(body).xquat, atol=1e-9)
        # Obj.pos is read where Fetch's step leaves the bodies: one 2 ms physics step behind
        # the state (at most 1.25 m/s x 2 ms)
        assert np.allclose(poses["object"].pos, scene.obj("object").pos, atol=0.003)
        # the target marker where Fetch's render puts it: at the scene's goal
        assert np.allclose(poses["target"].pos, world.goal_of(scene), atol=1e-9)
        # the gripper's parts: the gripper link and its two fingers, each at its own body
        bodies = [model.body(p.body).name for p in view.parts() if p.slot is None]
        assert bodies == [
            "robot0:gripper_link",
            "robot0:r_gripper_finger_link",
            "robot0:l_gripper_finger_link",
        ]
        for k, body in enumerate(bodies):
            assert np.allclose(poses[f"{EFFECTOR}/{k}"].pos, data.body(body).xpos, atol=1e-9)
            assert np.allclose(poses[f"{EFFECTOR}/{k}"].quat, data.body(body).xquat, atol=1e-9)
    # the object was carried: its pose after the lift is 5 cm higher than at the start
    z0 = view.poses(demo.scenes[0])[0].pos[2]
    assert view.poses(demo.scenes[t])[0].pos[2] > z0 + 0.05


def test_meshes_are_the_size_of_the_models_geoms(world):
    view = world.view3d
    model, _ = world.physics(world._open())
    for shape, body in (("object", "object0"), ("table", "table0"), ("distractor0", "distractor0")):
        (g,) = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body(body).id]
        size = model.geom_size[g]
        assert np.allclose(view.mesh(shape).bounds, [-size, size], atol=1e-9), shape
    # the target: a sphere of the site's radius (a uv sphere: within 1 % across)
    r = model.site_size[model.site("target0").id][0]
    assert np.allclose(view.mesh("target").bounds, [[-r] * 3, [r] * 3], rtol=0.01, atol=1e-4)
    # the gripper link: the model's own mesh vertices, unchanged in number
    (g,) = [g for g in range(model.ngeom) if model.geom_bodyid[g] == view.parts()[-3].body]
    assert model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
    mesh = view.mesh(f"{EFFECTOR}/0")
    assert len(mesh.vertices) == model.mesh_vertnum[model.geom_dataid[g]]
    assert len(mesh.faces) == model.mesh_facenum[model.geom_dataid[g]]
    # a finger: its box where the model puts it in the finger's frame
    finger = view.parts()[-2]
    (g,) = [g for g in range(model.ngeom) if model.geom_bodyid[g] == finger.body]
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[g])
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    placed = corners * model.geom_size[g] @ rot.reshape(3, 3).T + model.geom_pos[g]
    assert np.allclose(finger.mesh.bounds, [placed.min(0), placed.max(0)], atol=1e-9)


def test_colours_are_the_scenes_looks(world):
    view = world.view3d
    for shift in ("object_ti", "distractor_ti"):
        scene = world.test_task(shift, 0).scene
        poses = view.poses(scene)
        present = {o.slot for o in scene.objects if o.present}
        assert {p.slot for p in poses if not p.slot.startswith(EFFECTOR)} == present
        for p in poses:
            if p.slot in present:
                colour = scene.obj(p.slot).value("colour")
                assert p.colour == colour and p.rgba == (*PALETTE[colour], 1.0)
                assert view.look(p.shape, p.colour).rgba == p.rgba
            else:
                assert p.colour == "as built"
        if shift == "distractor_ti":  # the added block where the scene puts it
            (block,) = [p for p in poses if p.slot == "distractor0"]
            assert np.allclose(block.pos, scene.obj("distractor0").pos, atol=1e-6)


def test_an_action_is_drawn_as_the_grippers_motion(world, demo):
    view = world.view3d
    for t in (0, _lifted(world, demo)):
        before, after = demo.scenes[t], demo.scenes[t + 1]
        origin, vector = view.arrow(before, demo.actions[t], after)
        grip = [np.array(_physics(world, s).site("robot0:grip").xpos) for s in (before, after)]
        assert np.allclose(origin, grip[0], atol=1e-9)
        assert np.allclose(np.add(origin, vector), grip[1], atol=1e-9)


def test_robosuite_stack_is_drawn_from_its_own_model():
    """The same view on another package's model: robosuite's textured cubes in the colours
    their textures show (cube A red, cube B green), the gripper's bodies, poses at the bodies."""
    world = sim.get_world("robosuite:Stack")
    view, scene = world.view3d, world.train_task(0).scene
    rgb = {p.name: p.rgba[:3] for p in view.parts()}
    assert rgb["cubeA"][0] > max(rgb["cubeA"][1:]) + 0.2
    assert rgb["cubeB"][1] > max(rgb["cubeB"][0], rgb["cubeB"][2]) + 0.1
    data = _physics(world, scene)
    poses = {p.slot: p for p in view.poses(scene)}
    gripper = [p for p in view.parts() if p.slot is None]
    assert len(gripper) >= 3 and set(poses) == {"cubeA", "cubeB", "table"} | {
        p.name for p in gripper
    }
    for part in view.parts():
        if part.name in poses:
            assert np.allclose(poses[part.name].pos, data.xpos[part.body], atol=1e-9)
    # the table's top face at the view's centre height
    top = poses["table"].pos[2] + view.mesh("table").bounds[1][2]
    assert abs(top - view.centre_m[2]) < 1e-6
