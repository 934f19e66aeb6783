"""The loop's steps on nav2d (the cheapest paper world): TR feedback and `other` shifts, a
record through its stages, the simulated user's accuracy, same seed same record, large searches
recorded as rows, and one task giving one answer through `dfa run`, the page and the
experiment."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import rerun as rr

from dfa_viz.loop import run_loop
from dfa_viz.run_record import RunRecord
from dfa_viz.users import SimulatedUser
from policy import failing_test_task


def test_tr_feedback_augments_nothing(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_tr", 0)
    record = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0)
    assert [lab.relevant for lab in record.feedback.labels] == [True]
    assert record.adaptation.augmented == ()


def test_other_shift_has_no_feedback_to_give(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "other", 0)
    record = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0)
    assert record.to_json()["counterfactual"] == [] and record.feedback.labels == ()


def test_a_record_passes_through_its_stages(nav, nav_policy):
    from dfa_viz.loop import demonstrated, judged, start

    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    r = start(nav, nav_policy, task, shift="object_ti", seed=0)
    assert isinstance(r, RunRecord) and r.stage == "judge"
    assert judged(r, False).stage == "solved" and r.stage == "judge"  # a new record each time
    r = judged(r, True)
    assert r.stage == "demonstrate"
    r = demonstrated(r, nav.demonstrate(task))
    assert r.stage == "diagnose"
    miss = dataclasses.replace(nav.demonstrate(task), success=False)
    with pytest.raises(Exception, match="does not succeed at what the task asks"):
        demonstrated(judged(start(nav, nav_policy, task, shift="object_ti", seed=0), True), miss)


def test_simulated_user_accuracy_flips_labels(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    edit = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0).edit
    always_wrong = SimulatedUser(nav, accuracy=0.0).label(task, edit)
    assert [lab.relevant for lab in always_wrong.labels] == [True]
    always_right = SimulatedUser(nav, accuracy=1.0).label(task, edit)
    assert [lab.relevant for lab in always_right.labels] == [False]


def test_same_seed_same_record(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 1)
    a = run_loop(nav, nav_policy, task, SimulatedUser(nav, seed=1), seed=1)
    b = run_loop(nav, nav_policy, task, SimulatedUser(nav, seed=1), seed=1)
    assert a.to_json() == b.to_json() and a.adaptation.losses == b.adaptation.losses


def test_large_searches_are_recorded_as_rows(nav, nav_policy, tmp_path, monkeypatch):

    from dfa_viz import recording

    monkeypatch.setattr(recording, "DETAIL_LIMIT", 5)
    monkeypatch.setattr(recording, "DETAIL_BEST", 2)
    task, _ = failing_test_task(nav, nav_policy, "other", 0)
    record = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0)
    recording.write_recording(tmp_path / "run.rrd", nav, record)
    rows, traces = 0, set()
    for chunk in rr.chunk.RrdReader(tmp_path / "run.rrd").store().stream():
        path = str(chunk.entity_path)
        if path == "/search/all":
            rows += chunk.num_rows
        elif path.startswith("/search/candidates/c"):
            traces.add(path)
    assert rows == len(record.diagnosis.result.tried) > 5
    assert len(traces) == 2  # no valid candidate here: only the two closest keep a trace


def test_one_task_gives_one_answer_through_dfa_run_the_page_and_the_experiment(nav, tmp_path):
    """The same counterfactual, the same variants and the same success figures, equal (not
    close): `dfa run`, the page's jobs and the experiment's Oracle run all call the loop's
    steps with the same defaults."""
    from dfa_viz.app.server import open_state, wait_idle
    from dfa_viz.assemble import run_once
    from dfa_viz.configs import RunArgs
    from dfa_viz.experiment import runner
    from policy.variants import acceptable_if_irrelevant

    cli = run_once(RunArgs(world="nav2d", shift="object_ti", seed=0, out=tmp_path), progress=False)

    state = open_state(session=tmp_path / "s", out=tmp_path)
    try:
        state.pick("nav2d", "object_ti", 0)
        wait_idle(state, timeout_s=1200)  # a ceiling: the job takes seconds
        state.judge(True)
        state.demonstrate(expert=True)
        wait_idle(state, timeout_s=1200)
        for c in state.record.edit.ordered:  # as the simulated user of `dfa run` marks it
            values = acceptable_if_irrelevant(nav, cli.task.reward, c.slot, c.concept)
            state.mark(c.slot, c.concept, relevant=False, acceptable=values)
        assert state.finetune()
        wait_idle(state, timeout_s=1200)
        page = state.record
    finally:
        state.close()

    row = runner.run_one(runner.RunSpec("nav2d", "object", "oracle", 25, 0))

    assert page.task == cli.task
    assert [c.edit for c in page.diagnosis.result.counterfactuals] == [
        c.edit for c in cli.diagnosis.result.counterfactuals
    ]
    assert page.feedback == cli.feedback
    for a, b in zip(page.adaptation.augmented, cli.adaptation.augmented, strict=True):
        assert a.scenes == b.scenes and np.array_equal(a.observations, b.observations)
    assert page.adaptation.losses == cli.adaptation.losses
    assert page.evaluation == cli.evaluation
    j = cli.to_json()
    assert row["success"] == f"{j['success_after']:.4g}"
    assert row["success_before"] == f"{j['success_before']:.4g}"
    assert row["success_all"] == f"{j['success_all_after']:.4g}"
    assert row["n_distinct"] == str(1 + len(cli.adaptation.augmented))
    assert row["final_loss"] == f"{cli.adaptation.losses[-1]:.6g}"
    assert j["success_after"] >= j["success_before"]  # 0.3 -> 0.4 measured


def test_dagger_rounds_finetune_again_on_the_states_the_finetuned_policy_visits(nav, nav_policy):
    import torch

    from dfa_viz.configs import AdaptConfig, Finetuning
    from dfa_viz.experiment.runner import Settings
    from dfa_viz.loop import adapt
    from sim.core import UserError

    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    plain = AdaptConfig(budget=4, finetuning=Finetuning(steps=30, steps_per_trajectory=1))
    record = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0, config=plain)
    rounds = dataclasses.replace(
        plain, finetuning=Finetuning(steps=30, steps_per_trajectory=1, dagger_rounds=2)
    )
    assert rounds.total_steps == 3 * plain.total_steps == 90
    done = {}
    for name, config in (("plain", plain), ("rounds", rounds)):
        done[name] = adapt(
            nav, nav_policy, task, record.demo, record.feedback, config=config, seed=0
        )
    assert len(done["plain"].losses) == 30 and len(done["rounds"].losses) == 90
    same = [[t.scenes for t in done[n].augmented] for n in ("plain", "rounds")]
    assert same[0] == same[1] and len(same[0]) == 3  # the same variants
    weights = zip(
        done["plain"].policy.net.state_dict().values(),
        done["rounds"].policy.net.state_dict().values(),
        strict=True,
    )
    assert not all(torch.equal(a, b) for a, b in weights)
    assert "dagger_rounds" not in Settings().to_dict()["finetuning"]  # old folders read the same
    assert Settings(rounds.finetuning).to_dict()["finetuning"]["dagger_rounds"] == 2
    with pytest.raises(UserError, match="--dagger-rounds must be 0 or more"):
        Finetuning(dagger_rounds=-1).check()
