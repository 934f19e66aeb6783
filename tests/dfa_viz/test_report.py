"""The evaluation is said in one sentence, by the terminal report and the recording alike."""

from __future__ import annotations

import numpy as np

from dfa_viz.recording import task_text
from dfa_viz.report import evaluation_sentence, format_report
from dfa_viz.run_record import Evaluation, RunRecord
from policy.evaluate import Score
from sim import get_world


def _record() -> RunRecord:
    world = get_world("nav2d")
    task = world.test_task("object_ti", 0)
    rollout = world.rollout(task, lambda obs: np.zeros((len(obs), world.action_dim), np.float32))
    before = Score(shifted=(True, False, False, False), overall=(True, False))
    after = Score(shifted=(True, True, True, False), overall=(True, True))
    ev = Evaluation(before, after)
    return RunRecord("nav2d", "object_ti", 0, task, rollout, failed=True, evaluation=ev)


def test_the_sentence_gives_both_scores_before_and_after():
    ev = _record().evaluation
    assert evaluation_sentence(ev) == (
        "success on 4 fresh tasks with the shift: 25% -> 75% (on 2 from all you want: 50% -> 100%)"
        "; of 4 distinct, 2 newly solved and 0 newly failed (a rise this large by chance: "
        "p = 0.25, exact McNemar)"
    )
    assert "25% → 75%" in evaluation_sentence(ev, "→")


def test_the_report_and_the_recording_say_the_same_sentence():
    record = _record()
    ev = record.evaluation
    assert f"  {evaluation_sentence(ev)}" in format_report(record).splitlines()
    assert f"- {evaluation_sentence(ev, '→')}" in task_text(record).splitlines()
