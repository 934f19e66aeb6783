"""The sweep's lean lockstep rollouts give what World.rollout_batch gives: the same success,
the same actions wherever an episode is still going, the same frames through the policy; the
expert's actions replayed without rendering are judged the same."""

from __future__ import annotations

import numpy as np
import pytest

from policy import base_policy
from search.sweep import added_slot, cell_keys, key_edit, moved, sweep_tasks
from search.sweep.rollouts import replay_success, roll
from sim import get_world


def _edited(world, tasks):
    """Each task unedited and with every single cell that changes it."""
    out_tasks, scenes = [], []
    for task in tasks:
        edits = [key_edit(task.scene, k) for k in cell_keys(world.space)]
        for e in [None, *(e for e in edits if e is not None)]:
            out_tasks.append(task)
            scenes.append(task.scene if e is None else world.apply(task.scene, e))
            slot = None if e is None else added_slot(e)
            for pos in [] if slot is None else world.in_the_way(task, slot)[:3]:
                out_tasks.append(task)
                scenes.append(world.apply(moved(task.scene, e, pos), e))
    return out_tasks, scenes


@pytest.mark.parametrize("name", ["nav2d", "doorkey"])
def test_lean_rollouts_match_rollout_batch(name):
    world = get_world(name)
    policy = base_policy(world)
    tasks, scenes = _edited(world, sweep_tasks(world, 2))
    seen = {"lean": [], "batch": []}

    def counting(key):
        def act(obs):
            seen[key].append(len(obs))
            return policy.act(obs)

        return act

    runs = roll(world, counting("lean"), tasks, scenes)
    trajs = world.rollout_batch(tasks, counting("batch"), scenes=scenes)
    assert seen["lean"] == seen["batch"]  # the same batches through the policy
    assert [r.success for r in runs] == [t.success for t in trajs]
    assert any(not r.success for r in runs) and any(r.success for r in runs)
    for r, t in zip(runs, trajs, strict=True):
        live = np.array([not world.done(s) for s in t.scenes[:-1]])
        assert np.array_equal(r.live, live)
        assert np.array_equal(r.actions[live], t.actions[live])
    if name == "doorkey":
        assert any(not r.live.all() for r in runs)  # some episodes end early

    demos = [world.demonstrate(t) for t in tasks]
    actions = np.stack([d.actions for d in demos])  # (B, T)
    calls = iter(range(world.horizon))

    def replay(obs):
        return actions[:, next(calls)]

    expected = [t.success for t in world.rollout_batch(tasks, replay, scenes=scenes)]
    got = replay_success(world, tasks, scenes, actions)
    assert got == expected
    if name == "doorkey":
        assert not all(got)  # the demonstration replayed walks into lava put on its path
