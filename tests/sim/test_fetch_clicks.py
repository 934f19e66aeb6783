"""Waypoints of Fetch's gripper clicked on its frames (demo_input "effector", sim.mjworld.clicks):
a click meets what the camera drew at that pixel, a second click in the low view places a
target in the air, and the gripper led through the clicks does the task.

Where a slot is drawn is read from the frames themselves: the pixels that change when only its
colour does."""

from __future__ import annotations

import numpy as np
import pytest
from clicked import click_on, drawn

import sim
from sim.core import UserError, Waypoint
from sim.mjworld.clicks import ABOVE_M

PICK = "fetch:FetchPickAndPlace-v4"
TABLE_TOP_M = 0.4  # Fetch's table top (the block rests with its centre 0.025 m over it)


@pytest.fixture(scope="module")
def world():
    return sim.get_world(PICK)


def _task(world, air: bool):
    """The first training task whose goal is in the air (or on the table)."""
    for seed in range(50):
        task = world.train_task(seed=seed)
        if (world.goal_of(task.scene)[2] > TABLE_TOP_M + 0.05) == air:
            return task
    raise AssertionError("no such task in 50 seeds")


def test_a_click_on_the_block_grasps_it_and_one_on_the_table_is_a_point_over_it(world):
    scene = _task(world, air=False).scene
    grasp = world.effector_waypoint(scene, *click_on(world, drawn(world, scene, "object"), 0), None)
    assert grasp.grasp == "object" and grasp.on == "the object"
    assert grasp.pos == pytest.approx(scene.obj("object").pos[:3], abs=1e-3)
    table = drawn(world, scene, "table")
    table[: table.shape[0] * 3 // 4] = False  # its near edge, clear of the block and target
    bare = world.effector_waypoint(scene, *click_on(world, table, 0), grasp)
    assert bare.grasp == "" and bare.on == "the table"
    assert bare.pos[2] == pytest.approx(TABLE_TOP_M + ABOVE_M, abs=0.005)
    floor = world.effector_waypoint(scene, 0.01, 0.99, bare)  # the first view's lower left
    assert floor.on == "the floor" and floor.pos[2] == pytest.approx(ABOVE_M, abs=0.005)


def test_a_second_click_in_the_low_view_places_a_target_in_the_air(world):
    scene = _task(world, air=True).scene
    goal = world.goal_of(scene)
    target = drawn(world, scene, "target")
    first = world.effector_waypoint(scene, *click_on(world, target, 0), None)
    assert np.linalg.norm(np.subtract(first.pos, goal)) > 0.05  # the first view: along a line
    placed = world.effector_waypoint(scene, *click_on(world, target, 1), first)
    assert np.linalg.norm(np.subtract(placed.pos, goal)) < 0.02, (placed.pos, goal)
    with pytest.raises(UserError, match="click the point in the first view, then"):
        world.effector_waypoint(scene, *click_on(world, target, 1), None)


@pytest.mark.parametrize("air", [False, True], ids=["table target", "target in the air"])
def test_the_gripper_led_through_the_clicks_puts_the_block_on_the_target(world, air):
    task = _task(world, air)
    scene = task.scene
    block, target = drawn(world, scene, "object"), drawn(world, scene, "target")
    clicks = [(block, 0), (target, 0)] + ([(target, 1)] if air else [])
    waypoints: list[Waypoint] = []
    for mask, view in clicks:
        last = waypoints[-1] if waypoints else None
        w = world.effector_waypoint(scene, *click_on(world, mask, view), last)
        assert w.replaces == (view > 0)  # a low-view click places the one before
        waypoints[len(waypoints) - w.replaces :] = [w]
    demo = world.follow(task, waypoints)
    assert demo.success, demo.scenes[-1].obj("object").pos
    assert len(demo.actions) == world.horizon and np.abs(demo.actions).max() <= 1.0
    assert not world.follow(task, waypoints[:1]).success  # grasped but never carried
