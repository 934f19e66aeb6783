"""DoorKey's task generator: training layouts, shifts, fresh tasks from R', placements."""

from __future__ import annotations

import numpy as np
import pytest

from sim.core import PRESENCE, SHIFTS, Obj, Scene, UserError
from sim.doorkey.expert import path_cells, solvable
from sim.doorkey.layout import OBJ_COLOURS, parse, rows_of
from sim.doorkey.tasks import TRAIN_COLOURS, TRAIN_LAYOUTS, _colours, neighbours, unseen_rows
from sim.doorkey.world import DoorKeyWorld

SEEDS = range(4)


@pytest.fixture(scope="module")
def world() -> DoorKeyWorld:
    return DoorKeyWorld()


def _with_lava(scene: Scene, slot: str, colour: str, cell) -> Scene:
    return scene.with_obj(Obj(slot, True, (("colour", colour),), (float(cell[0]), float(cell[1]))))


def _train_like(world, task):
    """The training task on the same key, door and goal rows as `task`."""
    rows = rows_of(task.scene)
    trains = map(world.train_task, range(len(TRAIN_LAYOUTS)))
    (train,) = [t for t in trains if rows_of(t.scene) == rows]
    return train


def test_training_layouts_vary_the_goal_and_key_rows(world):
    tasks = [world.train_task(seed) for seed in range(30)]
    assert world.cloning.demonstrations == len(tasks) == len(TRAIN_LAYOUTS)
    assert [rows_of(t.scene)["goal"] for t in tasks] == [8, 2, 4, 6, 3, 7, 5, 1, 9, 10] * 3
    assert [rows_of(t.scene)["key"] for t in tasks] == [5] * 10 + [4] * 10 + [6] * 10
    assert {rows_of(t.scene)["door"] for t in tasks} == {3}
    assert world.train_task(30).scene == world.train_task(0).scene
    assert rows_of(world.train_task().scene) == {"key": 5, "door": 3, "goal": 8}
    demos = [world.demonstrate(t) for t in tasks]
    assert all(d.success for d in demos)
    assert len({d.actions.tobytes() for d in demos}) == 30  # thirty different action sequences
    for t in tasks:
        assert world.space.encode(t.scene).tolist() == world.space.encode(tasks[0].scene).tolist()
    assert unseen_rows("goal") == () and set(unseen_rows("key")) == set(range(1, 11)) - {4, 5, 6}
    assert set(unseen_rows("door")) == set(range(1, 11)) - {3}


def test_shift_rewards_and_causes(world):
    for seed in SEEDS:
        ti, tr = world.test_task("object_ti", seed), world.test_task("object_tr", seed)
        train = _train_like(world, ti)
        slot, concept = ti.cause
        assert concept == "colour" and slot in ("key", "door", "goal")
        assert ti.scene.obj(slot).value("colour") != train.scene.obj(slot).value("colour")
        undone = ti.scene.with_obj(ti.scene.obj(slot).with_value("colour", TRAIN_COLOURS[slot]))
        assert undone == train.scene  # undoing the shift gives back a training scene
        assert ti.reward.allowed_values(slot, "colour") == OBJ_COLOURS
        assert not ti.reward.is_relevant(slot, "colour")
        slot, _ = tr.cause
        assert tr.reward.allowed_values(slot, "colour") == (tr.scene.obj(slot).value("colour"),)
        assert tr.reward.is_relevant(slot, "colour")

        dti = world.test_task("distractor_ti", seed)
        assert dti.cause == ("lava0", PRESENCE) and dti.scene.obj("lava0").present
        assert dti.reward.allowed_values("lava1", PRESENCE) == ("present", "absent")
        assert dti.reward.allowed_values("lava2", "colour") == ("orange", "pink")
        # off the path: the expert does exactly what it does without the lava
        train = _train_like(world, dti)
        assert np.array_equal(world.demonstrate(dti).actions, world.demonstrate(train).actions)

        dtr = world.test_task("distractor_tr", seed)
        assert dtr.cause == ("lava0", PRESENCE) and dtr.reward.avoid == ("lava0",)
        assert dtr.reward.is_relevant("lava0", PRESENCE)
        assert world.demonstrate(dtr).success

        other = world.test_task("other", seed)
        assert other.cause is None
        moved = [s for s in ("key", "door", "goal") if rows_of(other.scene)[s] in unseen_rows(s)]
        assert len(moved) == 1 and moved[0] in ("key", "door")
        kept = {s: r for s, r in rows_of(other.scene).items() if s != moved[0]}
        trains = [rows_of(world.train_task(i).scene) for i in range(len(TRAIN_LAYOUTS))]
        assert any(all(rows[s] == r for s, r in kept.items()) for rows in trains)
        train = world.train_task()
        assert world.space.encode(other.scene).tolist() == world.space.encode(train.scene).tolist()
    with pytest.raises(UserError):
        world.test_task("sideways", 0)


def test_lava_lies_next_to_the_path_or_one_cell_further_when_avoided(world):
    """Distractors are in view of what the agent does: TI lava touches the expert's path, the
    lava a TR reward avoids sits just outside the cells next to it."""
    for seed in range(8):
        for shift in ("distractor_ti", "distractor_tr"):
            task = world.test_task(shift, seed)
            path = set(path_cells(parse(task.scene)))
            near = set().union(*(neighbours(c) for c in path))
            for slot in ("lava0", "lava1", "lava2"):
                o = task.scene.obj(slot)
                if not o.present:
                    continue
                cell = (int(o.pos[0]), int(o.pos[1]))
                if shift == "distractor_ti":
                    assert cell in near - path
                else:
                    assert cell not in near and neighbours(cell) & near


def test_fresh_tasks_follow_the_reward(world):
    for shift in SHIFTS:
        task = world.test_task(shift, 1)
        for fresh in world.fresh_tasks(task, 6, seed=4):
            assert fresh.reward == task.reward and fresh.shift == shift
            for slot, concept, values in task.reward.allowed:
                o = fresh.scene.obj(slot)
                now = (
                    ("present" if o.present else "absent")
                    if concept == PRESENCE
                    else o.value(concept)
                )
                if concept == PRESENCE or o.present:
                    assert now in values


def test_fresh_tasks_can_take_the_training_layouts(world):
    for shift in ("object_ti", "distractor_ti"):
        task = world.test_task(shift, 1)
        same = world.fresh_tasks(task, 12, seed=4)
        moved = world.fresh_tasks(task, 12, seed=4, layouts="train")
        assert {rows_of(f.scene)["goal"] for f in same} == {rows_of(task.scene)["goal"]}
        rows = {tuple(rows_of(f.scene).values()) for f in moved}
        assert rows <= set(TRAIN_LAYOUTS) and len(rows) >= 4
        for a, b in zip(same, moved, strict=True):
            assert _colours(a.scene) == _colours(b.scene)
            assert solvable(parse(b.scene))


def test_placements_leave_the_demonstration_unchanged(world):
    task = world.train_task()
    demo = world.demonstrate(task)
    cells = world.placements(task, "lava1", demo)
    visited = {parse(s).agent for s in demo.scenes}
    assert cells and not visited & {(int(c), int(r)) for c, r in cells}
    for cell in cells[::6]:
        start = _with_lava(demo.scenes[0], "lava1", "pink", cell)
        replay = [start]
        for a in demo.actions:
            replay.append(world.step_batch([replay[-1]], a[None])[0])
        assert [s.agent for s in replay] == [s.agent for s in demo.scenes]
        assert world.success(task, replay)
