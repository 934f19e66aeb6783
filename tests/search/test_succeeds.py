"""A world whose counterfactual "succeeds" (closed-loop control): an edit is valid exactly when
the policy, rolled out from the edited scene, does the task."""

import numpy as np
import pytest

from policy import failing_test_task
from search import SearchConfig, SearchResult, counterfactual_search, singles
from search.lockstep import rollout_lockstep
from sim.core import EMPTY, Change, Edit, UserError
from sim.nav2d.world import Nav2DWorld


class ClosedLoopNav2D(Nav2DWorld):
    """nav2d judged the way a closed-loop MuJoCo world is (a user's world may declare it)."""

    counterfactual = "succeeds"


@pytest.fixture(scope="module")
def closed():
    return ClosedLoopNav2D()


@pytest.mark.parametrize("shift", ["object_ti", "distractor_tr"])
def test_an_edit_is_valid_exactly_when_its_rollout_does_the_task(closed, nav_policy, shift):
    for seed in range(3):
        task, _ = failing_test_task(closed, nav_policy, shift, seed)
        demo = closed.demonstrate(task)
        edits = [EMPTY, *singles(closed.space, task.scene)]
        cands = rollout_lockstep(
            closed, nav_policy, task.scene, demo, edits, epsilon=closed.epsilon, task=task
        )
        scenes = closed.apply_batch(task.scene, edits)
        runs = closed.rollout_batch([task] * len(edits), nav_policy, scenes=scenes)
        assert [c.valid for c in cands] == [r.success for r in runs]
        assert not cands[0].valid and cands[0].dropped_at == closed.horizon  # the task fails
        assert any(c.valid for c in cands)
        for cand, run in zip(cands, runs, strict=True):  # the distances are the rollout's own
            compared = ~np.isnan(cand.distances)
            want = np.abs(run.actions - demo.actions).sum(axis=1)[compared]
            np.testing.assert_allclose(cand.distances[compared], want, rtol=1e-5, atol=1e-5)


def test_the_search_answers_in_the_worlds_terms(closed, nav, nav_policy):
    task, _ = failing_test_task(closed, nav_policy, "object_ti", 0)
    demo = closed.demonstrate(task)
    config = SearchConfig(max_size=1)
    result = counterfactual_search(closed, nav_policy, task.scene, demo, config=config, task=task)
    plain = counterfactual_search(nav, nav_policy, task.scene, demo, config=config, task=task)
    assert result.criterion == "succeeds" and plain.criterion == "follows"
    assert result.found and result.size == 1
    slot, concept = task.cause
    undo = Change(
        slot,
        concept,
        task.scene.obj(slot).value(concept),
        nav.train_task().scene.obj(slot).value(concept),
    )
    assert Edit.of(undo) in {c.edit for c in result.counterfactuals}
    back = SearchResult.from_json(result.to_json())
    assert back.criterion == "succeeds"
    with pytest.raises(UserError, match="criterion 'nearby'"):
        SearchResult.from_json({**result.to_json(), "criterion": "nearby"})
    none = SearchResult((), result.tried, None, 1, criterion="succeeds")
    assert "makes the policy do the task" in none.summary()


class CountingNav2D(ClosedLoopNav2D):
    """Counts the scenes it steps."""

    stepped = 0

    def step_batch(self, scenes, actions):
        self.stepped += len(scenes)
        return super().step_batch(scenes, actions)


def test_larger_edits_are_not_rolled_out_once_a_size_has_an_answer(nav_policy):
    world = CountingNav2D()
    task, _ = failing_test_task(world, nav_policy, "object_ti", 0)
    demo = world.demonstrate(task)
    world.stepped = 0
    result = counterfactual_search(world, nav_policy, task.scene, demo, task=task)
    ones = len(singles(world.space, task.scene))
    assert result.size == 1 and len(result.tried) == ones
    assert world.stepped <= ones * world.horizon  # no size-2 edit was rolled out
