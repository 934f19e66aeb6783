import pytest

from dfa_viz.loop import run_loop
from dfa_viz.users import SimulatedUser
from policy import failing_test_task

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("shift", ["object_ti", "distractor_ti"])
def test_feedback_and_finetuning_raise_success(nav, nav_policy, shift, learns):
    """Measured with the committed base policy (5 seeds): object_ti 0.58 -> 1.0, distractor_ti
    0.64 -> 1.0."""
    pairs = []
    for seed in range(5):
        task, _ = failing_test_task(nav, nav_policy, shift, seed)
        report = run_loop(nav, nav_policy, task, SimulatedUser(nav, seed=seed), seed=seed)
        assert report.failed and report.search.found
        assert [lab.relevant for lab in report.feedback.labels] == [False]
        assert report.n_augmented > 0
        pairs.append((report.success_before, report.success_after))
    learns(pairs, min_after=0.85, min_gain=0.2)


def test_tr_feedback_augments_nothing(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_tr", 0)
    report = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0)
    assert [lab.relevant for lab in report.feedback.labels] == [True]
    assert report.n_augmented == 0


def test_other_shift_has_no_feedback_to_give(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "other", 0)
    report = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0)
    assert report.to_dict()["counterfactual"] == [] and report.feedback.labels == ()


def test_simulated_user_accuracy_flips_labels(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    edit = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0).search.best.edit
    always_wrong = SimulatedUser(nav, accuracy=0.0).label(task, edit)
    assert [lab.relevant for lab in always_wrong.labels] == [True]
    always_right = SimulatedUser(nav, accuracy=1.0).label(task, edit)
    assert [lab.relevant for lab in always_right.labels] == [False]


def test_same_seed_same_report(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 1)
    a = run_loop(nav, nav_policy, task, SimulatedUser(nav, seed=1), seed=1)
    b = run_loop(nav, nav_policy, task, SimulatedUser(nav, seed=1), seed=1)
    assert a.to_dict() == b.to_dict() and a.losses == b.losses


def test_large_searches_are_recorded_as_rows(nav, nav_policy, tmp_path, monkeypatch):
    import rerun as rr

    from dfa_viz import recording
    from dfa_viz.recording import Recorder

    monkeypatch.setattr(recording, "DETAIL_LIMIT", 5)
    monkeypatch.setattr(recording, "DETAIL_BEST", 2)
    task, _ = failing_test_task(nav, nav_policy, "other", 0)
    rec = Recorder(tmp_path / "run.rrd", nav, task)
    report = run_loop(nav, nav_policy, task, SimulatedUser(nav), seed=0, observer=rec)
    rec.close()
    rows, traces = 0, set()
    for chunk in rr.chunk.RrdReader(tmp_path / "run.rrd").store().stream():
        path = str(chunk.entity_path)
        if path == "/search/all":
            rows += chunk.num_rows
        elif path.startswith("/search/candidates/c"):
            traces.add(path)
    assert rows == len(report.search.tried) > 5
    assert len(traces) == 2  # no valid candidate here: only the two closest keep a trace
