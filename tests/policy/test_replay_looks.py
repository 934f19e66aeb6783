"""The replayed training data re-rendered over the TI labels (`--replay-looks varied`), on nav2d:
each replayed trajectory on a layout finetuning may use shows an accepted look, never one the
evaluation holds out, with its actions kept; held-out layouts and TR feedback leave it as it
is; the loop finetunes on it; a wrong setting is one line."""

from __future__ import annotations

import numpy as np
import pytest

from dfa_viz.configs import AdaptConfig, Finetuning
from dfa_viz.experiment.runner import Settings
from dfa_viz.loop import adapt
from policy import failing_test_task, training_demos
from policy.heldout import plan
from policy.replay_looks import replay_for, varied
from policy.train import replayed
from sim.core import Feedback, Label, UserError


def _ti(task, relevant: bool = False) -> Feedback:
    slot, concept = task.cause
    return Feedback((Label(slot, concept, relevant),))


@pytest.fixture(scope="module")
def shifted(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    return task, replayed(nav, nav_policy, training_demos(nav))


def test_each_kept_trajectory_shows_an_accepted_look(nav, shifted):
    task, replay = shifted
    slot, concept = task.cause
    out = varied(nav, task, _ti(task), replay, seed=0)
    holdout = plan(nav, task, 0)
    held = holdout.held(slot, concept)
    assert len(out) == len(replay) and held
    looks = set()
    for before, after in zip(replay, out, strict=True):
        assert np.array_equal(before.actions, after.actions) and before.success == after.success
        if not holdout.keeps(nav, before.scenes[0]):
            assert after is before  # a held-out layout stays in its training look
            continue
        look = after.scenes[0].obj(slot).value(concept)
        assert look != before.scenes[0].obj(slot).value(concept) and look not in held
        assert all(s.obj(slot).value(concept) == look for s in after.scenes)
        assert not np.array_equal(before.observations, after.observations)
        looks.add(look)
    assert len(looks) >= 2  # the accepted looks are spread over the replay
    again = varied(nav, task, _ti(task), replay, seed=0)
    assert all(
        np.array_equal(a.observations, b.observations) for a, b in zip(out, again, strict=True)
    )


def test_tr_feedback_and_the_training_looks_replay_as_given(nav, nav_policy, shifted):
    task, replay = shifted
    known = training_demos(nav)
    assert varied(nav, task, _ti(task, relevant=True), replay, seed=0) == list(replay)
    args = (nav, nav_policy, task, _ti(task), known)
    assert replay_for(*args, looks="training", share=0.5, seed=0) == list(replay)
    assert replay_for(*args, looks="varied", share=0.0, seed=0) == []


def test_the_loop_finetunes_on_it(nav, nav_policy, shifted):
    task, _ = shifted
    demo = nav.demonstrate(task)
    runs = {
        looks: adapt(
            nav,
            nav_policy,
            task,
            demo,
            _ti(task),
            config=AdaptConfig(5, Finetuning(replay_looks=looks)),
            seed=0,
        )
        for looks in ("training", "varied")
    }
    same = [t.scenes for t in runs["training"].augmented]
    assert same == [t.scenes for t in runs["varied"].augmented]  # the budget's trajectories
    assert runs["training"].losses != runs["varied"].losses  # what is replayed is not


def test_a_wrong_setting_is_one_line(nav):
    with pytest.raises(UserError, match="--replay-looks is training, varied, painted, not"):
        Finetuning(replay_looks="spread").check()  # type: ignore[arg-type]
    painted = Finetuning(replay_looks="painted")
    with pytest.raises(UserError, match="nav2d draws only its named colours: training or varied"):
        painted.check(nav)
    assert painted.check() is painted  # no world: only the name is checked
    assert "replay_looks" not in Settings().to_dict()["finetuning"]
    varied_doc = Settings(finetuning=Finetuning(replay_looks="varied")).to_dict()
    assert varied_doc["finetuning"]["replay_looks"] == "varied"
