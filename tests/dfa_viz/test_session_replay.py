"""Sessions replayed: a session's events rebuild the loop's state, a search cut off by a crash
runs again on resume, and "Succeeded" ends the task."""

from __future__ import annotations

import json

import pytest

from dfa_viz.app.sessions import LOG
from dfa_viz.configs import AdaptConfig, Finetuning

QUICK = AdaptConfig(budget=5, finetuning=Finetuning(steps=20))  # a short finetuning for tests


def _wait(state) -> None:
    """Until the page's job is done (a ceiling of 20 minutes only ends one that never is)."""
    from dfa_viz.app.server import wait_idle

    wait_idle(state, timeout_s=1200)


@pytest.mark.slow
def test_replaying_a_session_rebuilds_the_loop_state(tmp_path, nav_policy):
    from dfa_viz.app.server import open_state

    state = open_state(session=tmp_path / "s", out=tmp_path, adapt=QUICK)
    state.pick("nav2d", "distractor_ti", 0)
    _wait(state)
    state.judge(True)
    state.demonstrate(expert=True)
    _wait(state)
    state.mark("distractor", "presence", relevant=False, acceptable=("present",))
    assert state.finetune()
    _wait(state)
    before = state.snapshot().record
    assert state.recording.is_file() and state.recording.parent == tmp_path
    state.close()

    again = open_state(session=tmp_path / "s", out=tmp_path)
    run = again.snapshot().record
    assert again.snapshot().stage == "adapted"
    assert run.task == before.task and run.demo.equals(before.demo)
    assert [c.edit for c in run.diagnosis.result.counterfactuals] == [
        c.edit for c in before.diagnosis.result.counterfactuals
    ]
    assert run.diagnosis.counterfactual.equals(before.diagnosis.counterfactual)
    assert run.feedback == before.feedback
    assert run.adaptation.rollout.equals(before.adaptation.rollout)
    assert run.adaptation.losses == pytest.approx(before.adaptation.losses, abs=1e-6)
    assert run.evaluation == before.evaluation
    # the variants are made again from the settings the event kept: the same set
    assert [a.scenes for a in run.adaptation.augmented] == [
        a.scenes for a in before.adaptation.augmented
    ]
    again.close()


def test_a_search_cut_off_by_a_crash_runs_again_on_resume(tmp_path, nav_policy):
    from dfa_viz.app.server import open_state

    state = open_state(session=tmp_path / "s", out=tmp_path)
    state.pick("nav2d", "object_ti", 0)
    _wait(state)
    state.judge(True)
    state.demonstrate(expert=True)
    _wait(state)
    found = [c.edit for c in state.record.diagnosis.result.counterfactuals]
    state.close()
    log = tmp_path / "s" / LOG
    lines = log.read_text().splitlines(keepends=True)
    assert json.loads(lines[-1])["type"] == "search"
    log.write_text("".join(lines[:-1]))  # the server died during the search

    again = open_state(session=tmp_path / "s", out=tmp_path)
    _wait(again)  # resuming started the search again
    assert again.snapshot().stage == "feedback"
    assert [c.edit for c in again.record.diagnosis.result.counterfactuals] == found
    assert json.loads(log.read_text().splitlines()[-1])["type"] == "search"
    again.close()


def test_succeeded_ends_the_task(tmp_path, nav_policy):
    from dfa_viz.app.server import open_state
    from sim.core import UserError

    state = open_state(session=tmp_path / "s", out=tmp_path)
    state.pick("nav2d", "object_ti", 0)
    _wait(state)
    state.judge(False)
    assert state.snapshot().stage == "solved"
    with pytest.raises(UserError, match="the loop is at 'solved'"):
        state.demonstrate(expert=True)
    state.close()
