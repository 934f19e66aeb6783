"""Augmentation: variants over what the user called task-irrelevant, from the user's and the
training demonstrations, each a re-rendering of its source with the actions kept."""

from __future__ import annotations

import numpy as np
import pytest

from policy import augment, failing_test_task, training_demos
from policy import variants as A
from sim import get_world
from sim.core import ABSENT, PRESENCE, PRESENT, Feedback, Label
from sim.core.ops import transform


@pytest.fixture(scope="module")
def known(nav):
    return training_demos(nav)


def test_variants_rerender_every_state_and_keep_the_actions(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    slot, concept = task.cause
    values = nav.space.values(slot, concept)
    aug = augment(nav, task, demo, Feedback((Label(slot, concept, False, values),)), n=50)
    assert len(aug) == len(values) - 1  # the user's demonstration only: one per other value
    seen = {a.scenes[0].obj(slot).value(concept) for a in aug}
    assert seen == set(values) - {task.scene.obj(slot).value(concept)}
    for a in aug:
        assert np.array_equal(a.actions, demo.actions)
        assert all(s.obj(slot).value(concept) in seen for s in a.scenes)
        assert np.array_equal(a.observations, nav.render_batch(a.scenes))


def test_added_distractors_stay_off_the_path(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    demo = nav.demonstrate(task)
    label = Label("distractor", "presence", False, ("present", "absent"))
    aug = augment(nav, task, demo, Feedback((label,)), n=1000)
    places = nav.placements(task, "distractor", demo)
    # every look at every place, minus the test scene itself, plus the distractor removed
    assert places and len(aug) == 16 * len(places)
    for a in aug:
        d = a.scenes[0].obj("distractor")
        assert not d.present or d.pos in places


def test_tr_feedback_adds_nothing(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_tr", 0)
    demo = nav.demonstrate(task)
    slot, concept = task.cause
    assert augment(nav, task, demo, Feedback((Label(slot, concept, True),)), n=10) == []


def test_a_label_speaks_for_its_slots_kind():
    world = get_world("doorkey")
    what = A.from_feedback(world, Feedback((Label("lava1", "presence", False, ("absent",)),)))
    assert what.name == "lava.presence"
    assert what.members == tuple((f"lava{i}", "presence", ("absent",)) for i in range(3))


def test_variants_are_distinct_and_more_extend_fewer(nav, nav_policy, known):
    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    demo = nav.demonstrate(task)
    srcs = A.sources(task, demo, known)
    what = A.over(nav, task, nav.space.user_concept("distractor", "presence"))
    few = A.variants(nav, srcs, lambda i: what, 4, seed=3, like=task.scene)
    many = A.variants(nav, srcs, lambda i: what, 1000, seed=3, like=task.scene)
    assert many[:4] == few and len(many) > 100
    scenes = [transform(srcs[k].task.scene, ops) for k, ops in many]
    assert len(set(scenes)) == len(scenes)
    assert not {s.task.scene for s in srcs} & set(scenes), "no variant is a source scene"
    # small budgets spread over layouts: the first variants come from different sources
    assert len({k for k, _ in few}) == 4
    trajs = A.render(nav, srcs, few)
    for (k, _), t in zip(few, trajs, strict=True):
        np.testing.assert_array_equal(t.actions, srcs[k].demo.actions)
        assert t.observations.shape == srcs[k].demo.observations.shape
    filled = A.fill_budget(demo, trajs, 11)
    assert len(filled) == 11 and filled[0] is demo and filled[5] is demo


def test_sources_put_unseen_layouts_first(nav, nav_policy, known):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    srcs = A.sources(task, demo, known)
    assert len(srcs) == len(known) + 1
    user = [s.demo for s in srcs].index(demo)
    firsts = [s.task.scene for s in srcs[:user]]
    assert user >= 5
    for i, a in enumerate(firsts):
        assert not A.same_layout(a, task.scene)
        assert not any(A.same_layout(a, b) for b in firsts[:i])
    # every source keeps the test task's R' and its own scene
    assert all(s.task.reward == task.reward for s in srcs)
    assert all(s.task.scene == s.demo.scenes[0] for s in srcs)


def test_grouped_presence_variants_draw_from_a_huge_product():
    world = get_world("doorkey")
    task = world.test_task("distractor_ti", 0)
    demo = world.demonstrate(task)
    what = A.over(world, task, world.space.user_concept("lava0", "presence"))
    chosen = A.variants(world, [A.Source(task, demo)], lambda i: what, 30, seed=0, like=task.scene)
    assert len(chosen) == 30
    for _, ops in chosen:
        scene = transform(task.scene, ops)
        cells = [o.pos for o in scene.objects if o.present and o.slot.startswith("lava")]
        assert len(cells) == len(set(cells)), "no two lava tiles on one cell"


def test_an_informed_user_accepts_what_r_accepts(nav):
    task = nav.test_task("object_ti", 0)
    slot, concept = task.cause
    assert A.acceptable_if_irrelevant(nav, task.reward, slot, concept) == nav.space.accepted(
        task.reward, slot, concept
    )
    fixed = "colour" if concept == "shape" else "shape"  # R' fixes the other one
    assert len(nav.space.accepted(task.reward, slot, fixed)) == 1
    assert A.acceptable_if_irrelevant(nav, task.reward, slot, fixed) == nav.space.values(
        slot, fixed
    )


def test_the_first_variants_look_like_the_test_task(nav, nav_policy, known):
    """A source takes the test task's own looks before any other: a small budget holds what
    the user saw go wrong (measured: nav2d distractor_ti at 25 trajectories went from 0.68 to
    1.0 success on the shift when the variants put the test task's distractor first)."""
    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    demo = nav.demonstrate(task)
    srcs = A.sources(task, demo, known)
    what = A.over(nav, task, nav.space.user_concept("distractor", "presence"))
    chosen = A.variants(nav, srcs, lambda i: what, 8, seed=0, like=task.scene)
    look = task.scene.obj("distractor").values
    added = [transform(srcs[k].task.scene, ops).obj("distractor") for k, ops in chosen]
    assert all(d.present and d.values == look for d in added)


def test_spread_looks_go_through_the_accepted_values_over_the_layouts(nav, nav_policy, known):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    slot, concept = task.cause
    what = A.over(nav, task, nav.space.user_concept(slot, concept))
    accepted = dict(((s, c), v) for s, c, v in what.members)[slot, concept]
    likes = A.spread_looks(task.scene, what)
    own = task.scene.obj(slot).value(concept)
    assert likes[0] == task.scene and len(likes) == len(accepted) > 2
    assert sorted(s.obj(slot).value(concept) for s in likes) == sorted(accepted)
    srcs = A.sources(task, nav.demonstrate(task), known)
    n = len(accepted) * 2
    test_first = A.variants(nav, srcs, lambda i: what, n, seed=0, like=task.scene)
    spread = A.variants(nav, srcs, lambda i: what, n, seed=0, like=likes)

    def shown(chosen):
        return [transform(srcs[k].task.scene, ops).obj(slot).value(concept) for k, ops in chosen]

    assert set(shown(test_first)) == {own}  # every layout first in the test task's look
    trained = known[0].scenes[0].obj(slot).value(concept)  # the training demonstrations show it
    assert set(shown(spread)) | {trained} == set(accepted)  # every other accepted look shown
    held = A.Irrelevant(what.name, what.members, held=((slot, concept, (accepted[-1],)),))
    assert accepted[-1] not in {
        s.obj(slot).value(concept) for s in A.spread_looks(task.scene, held)
    }


def test_a_block_is_added_to_a_fetch_scene_whose_table_shares_the_targets_place():
    world = get_world("fetch:FetchPickAndPlace-v4")
    task = world.test_task("distractor_ti", 0)
    table, target = task.scene.obj("table").pos[:2], task.scene.obj("target").pos[:2]
    assert np.allclose(table, target)  # what once made every added block count as stacked
    demo = world.demonstrate(task)
    said = Feedback((Label("distractor0", PRESENCE, False, (PRESENT, ABSENT)),))
    aug = augment(world, task, demo, said, n=6)
    added = [a.scenes[0].obj("distractor0") for a in aug if a.scenes[0].obj("distractor0").present]
    assert len(aug) == 6 and len(added) >= 5
    assert len({o.pos[:2] for o in added}) > 1  # on more than one free spot
