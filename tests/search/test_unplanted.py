"""Unplanted failures: the compound generator's tasks are what they claim, the exhaustive ground
truth restores success when replayed, and both are the same for the same seed."""

import pytest

from search.unplanted import candidate_seed, draw, failing, ground_truth
from sim.core import PRESENCE, UserError


@pytest.fixture(scope="module")
def drawn(nav, nav_policy):
    return list(failing(nav, nav_policy, "compound", 3, seed=0))


def test_compound_tasks_differ_from_training_by_two_objects_and_fail(nav, nav_policy, drawn):
    assert len(drawn) == 3 and len({(u.task.scene, u.task.reward) for u in drawn}) == 3
    for u in drawn:
        train = nav.train_task(u.task.seed)
        assert len(u.changes) == 2 and len({c.slot for c in u.changes}) == 2
        assert nav.apply(u.task.scene, u.undo) == train.scene  # exactly two changes away
        differ = [
            (o.slot, c)
            for o, t in zip(u.task.scene.objects, train.scene.objects, strict=True)
            for c in ((PRESENCE,) if o.present != t.present else ())
            + tuple(k for (k, v), (_, w) in zip(o.values, t.values, strict=True) if v != w)
        ]
        assert sorted(differ) == sorted((c.slot, c.concept) for c in u.changes)
        assert u.task.reward == train.reward and u.task.cause is None
        assert not nav.rollout(u.task, nav_policy).success
        assert nav.demonstrate(u.task).success


def test_ground_truth_restores_success_when_replayed(nav, nav_policy, drawn):
    for u in drawn:
        gt = ground_truth(nav, nav_policy, u.task)
        assert gt.tried[0] > 0 and gt.tried[1] > 0
        if gt.size is None:
            continue
        assert all(e.size == gt.size for e in gt.edits) and set(gt.edits) <= gt.restoring
        for edit in gt.edits:
            edited = u.task.with_scene(nav.apply(u.task.scene, edit))
            assert nav.rollout(edited, nav_policy).success, str(edit)
        if gt.size == 2:  # nothing smaller restores it
            assert not any(e.size == 1 for e in gt.restoring)


def test_same_seed_same_tasks_and_truth(nav, nav_policy, drawn):
    again = list(failing(nav, nav_policy, "compound", 3, seed=0))
    assert [(u.task, u.changes) for u in again] == [(u.task, u.changes) for u in drawn]
    u = drawn[0]
    assert ground_truth(nav, nav_policy, u.task) == ground_truth(nav, nav_policy, again[0].task)
    other = draw(nav, "compound", candidate_seed(1, 0))
    assert other is not None and other[0].seed != u.task.seed


def test_a_policy_that_never_fails_is_one_line(nav, nav_policy):
    with pytest.raises(UserError, match="only 0 failing natural tasks among 5 candidates"):
        list(failing(nav, nav_policy, "natural", 1, tries=5))
    with pytest.raises(UserError, match="unknown kind"):
        list(failing(nav, nav_policy, "planted", 1))
