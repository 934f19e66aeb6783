"""The replayed data painted beyond the named colours (`--replay-looks painted`), on
FetchPickAndPlace's recoloured table: each trajectory varied on a layout finetuning may use is
drawn with the table in a colour of its own, kept PAINT_GAP from every colour no variant may
show (held out, or not accepted), its actions and scenes kept; held-out layouts stay as they
are; the same seed paints the same frames."""

from __future__ import annotations

import numpy as np
import pytest

import sim
from policy.heldout import plan
from policy.replay_looks import PAINT_GAP, paint_colours, painted, varied, varied_scenes
from policy.train import training_tasks
from sim.core import Feedback, Label

PICK = "fetch:FetchPickAndPlace-v4"


@pytest.fixture(scope="module")
def table_ti():
    """The object_ti task (the table recoloured), the user's TI label on the table's colour
    with what R' accepts, and expert demonstrations on 3 layouts finetuning may use and 1
    the evaluation holds out."""
    world = sim.get_world(PICK)
    task = world.test_task("object_ti", 0)
    slot, concept = task.cause
    feedback = Feedback(
        (Label(slot, concept, False, world.space.accepted(task.reward, slot, concept)),)
    )
    holdout = plan(world, task, 0)
    tasks = training_tasks(world)
    kept = [t for t in tasks if holdout.keeps(world, t.scene)][:3]
    held = [t for t in tasks if not holdout.keeps(world, t.scene)][:1]
    replay = [world.demonstrate(t, seed=t.seed) for t in kept + held]
    return world, task, feedback, replay


def test_each_varied_trajectory_is_painted_away_from_what_no_variant_may_show(table_ti):
    world, task, feedback, replay = table_ti
    slot, concept = task.cause
    assert (slot, concept) == ("table", "colour")
    scenes = varied_scenes(world, task, feedback, replay, seed=0)
    colours = paint_colours(world, task, feedback, replay, scenes, seed=0)
    assert sorted(colours) == sorted(scenes) == [0, 1, 2]  # kept layouts; the held-out one stays
    chosen = varied(world, task, feedback, replay, seed=0)
    held = plan(world, task, 0).held(slot, concept)
    accepted = world.space.accepted(task.reward, slot, concept)
    named = world.paints.rgb
    avoid = np.array([rgb for v, rgb in named.items() if v in held or v not in accepted])
    assert held and len(avoid) == len(held) + len(set(named) - set(accepted))
    for paint in colours.values():
        assert list(paint) == [slot]
        assert np.linalg.norm(avoid - np.array(paint[slot]), axis=1).min() >= PAINT_GAP
    assert len({p[slot] for p in colours.values()}) == 3  # a colour of its own each

    out = painted(world, task, feedback, replay, seed=0)
    for i, (before, after) in enumerate(zip(replay, out, strict=True)):
        assert np.array_equal(before.actions, after.actions) and before.success == after.success
        if i not in colours:
            assert after is before  # a held-out layout stays in its training look
            continue
        assert after.scenes == chosen[i].scenes  # the scenes keep the variant's named look
        frames = world.render_painted(after.scenes, [colours[i]] * len(after.scenes))
        assert np.array_equal(after.observations, frames)
        assert not np.array_equal(after.observations, chosen[i].observations)
    again = painted(world, task, feedback, replay, seed=0)
    assert all(
        np.array_equal(a.observations, b.observations) for a, b in zip(out, again, strict=True)
    )
