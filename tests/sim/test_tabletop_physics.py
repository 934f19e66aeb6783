"""Tabletop: the simulated pick-and-place, the expert, determinism and the 3D pose export."""

from __future__ import annotations

import numpy as np
import pytest

import sim
from sim.core import SHIFTS
from sim.tabletop import tasks as TK
from sim.tabletop.catalogue import SHAPES
from sim.tabletop.meshes import shape_mesh
from sim.tabletop.pose import object_poses
from sim.tabletop.world import SUCCESS_RADIUS_M


@pytest.fixture(scope="module")
def world():
    return sim.get_world("tabletop")


def _xy_dist(a, b) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))


def test_pick_place_carries_the_object_and_it_settles_on_the_goal(world):
    task = world.train_task()
    action = world.expert_action(task, task.scene)
    frames, after = world.step_with_frames(task.scene, action, every=5)
    k = frames.slots.index("object")
    assert frames.picked == "object"
    assert frames.pos.shape == (len(frames.times_s), len(frames.slots), 3)
    assert np.all(np.diff(frames.times_s) > 0)
    z = frames.pos[:, k, 2]
    assert z.max() > 0.1  # lifted over the table, not slid or teleported
    x = frames.pos[:, k, 0]
    assert np.any((x > -0.15) & (x < 0.15))  # seen in between on its way
    o, g = after.obj("object").pos, after.obj("goal").pos
    assert _xy_dist(o, g) < SUCCESS_RADIUS_M
    assert o[2] > 0.005  # resting on the pan's floor, above the table top
    assert abs(np.linalg.norm(o[3:7]) - 1) < 1e-5
    assert after.agent == (1.0,) and world.done(after)
    assert world.success(task, [task.scene, after])
    assert world.step_batch([after], np.zeros((1, 4), np.float32))[0] is after


def test_picking_empty_table_moves_nothing(world):
    task = world.train_task()
    after = world.step_batch([task.scene], np.array([[0.0, 0.3, 0.2, -0.2]], np.float32))[0]
    for before, now in zip(task.scene.objects, after.objects, strict=True):
        if before.present:
            assert _xy_dist(before.pos, now.pos) < 1e-3
    assert not world.success(task, [task.scene, after])


def test_picking_a_distractor_carries_it_instead(world):
    task = world.test_task("distractor_tr", 0)
    d = task.scene.obj("distractor0").pos
    g = task.scene.obj("goal").pos
    after = world.step_batch([task.scene], np.array([[d[0], d[1], g[0], g[1]]], np.float32))[0]
    assert _xy_dist(after.obj("distractor0").pos, g) < SUCCESS_RADIUS_M
    assert _xy_dist(after.obj("object").pos, task.scene.obj("object").pos) < 1e-3
    assert not world.success(task, [task.scene, after])


def test_expert_succeeds_on_sampled_tasks(world):
    tasks = [world.train_task()] + [world.test_task(s, k) for s in SHIFTS for k in range(8)]
    tasks += [f for s in SHIFTS for f in world.fresh_tasks(world.test_task(s, 0), 4, seed=1)]
    demos = [world.demonstrate(t) for t in tasks]
    rate = np.mean([d.success for d in demos])
    assert rate >= 0.95, [
        (t.shift, t.seed) for t, d in zip(tasks, demos, strict=True) if not d.success
    ]
    for d in demos:
        assert d.observations.shape == (2, 80, 80, 3) and d.actions.shape == (1, 4)


def test_same_seed_gives_identical_rollouts(world):
    for shift in SHIFTS:
        a = world.demonstrate(world.test_task(shift, 3))
        world.demonstrate(world.test_task("distractor_ti", 4))  # anything in between
        b = world.demonstrate(world.test_task(shift, 3))
        assert a.equals(b)


def test_rollout_batch_matches_single_rollouts(world):
    tasks = [world.train_task(0), world.train_task(1)]
    tasks += [world.test_task(s, k) for s in SHIFTS for k in range(3)]

    def act(obs):  # (B, 80, 80, 3) -> (B, 4): always the canonical training motion
        return np.tile(np.array([-0.23, 0.23, 0.23, -0.23], np.float32), (len(obs), 1))

    batch = world.rollout_batch(tasks, act)
    for t, traj in zip(tasks, batch, strict=True):
        assert traj.equals(world.rollout(t, act))
    canonical = [
        t.scene.obj("object").pos[:2] == TK.AREAS[TK.OBJECT_AREA]
        and t.scene.obj("goal").pos[:2] == TK.AREAS[TK.GOAL_AREA]
        for t in tasks
    ]
    assert any(canonical) and not all(canonical)
    assert [t.success for t in batch] == canonical  # it works exactly in the canonical layout


def test_object_poses_for_the_3d_view(world):
    task = world.test_task("distractor_ti", 1)
    poses = object_poses(task.scene)
    assert [p.slot for p in poses] == [o.slot for o in task.scene.objects if o.present]
    for p in poses:
        assert p.shape in SHAPES and len(p.rgba) == 4 and all(0 <= c <= 1 for c in p.rgba)
        assert p.pos[:2] in TK.AREAS.values() and p.quat == (1.0, 0.0, 0.0, 0.0)


def test_every_shape_has_a_mesh_standing_on_the_table():
    for name in SHAPES:
        m = shape_mesh(name)
        lo, hi = m.bounds
        assert abs(lo[2]) < 1e-9 and 0.005 <= hi[2] <= 0.08, name
        assert 0.02 <= max(hi[:2] - lo[:2]) <= 0.26, name
