"""The tabletop through the whole DFA loop: base policy, failing tasks, the planted cause found,
finetuning that helps, and `dfa run` writing a recording with the scene in 3D."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rerun as rr

from dfa_viz.cli import main
from dfa_viz.configs import AdaptConfig, Finetuning
from dfa_viz.loop import run_loop
from dfa_viz.users import SimulatedUser
from policy import base_policy, failing_test_task
from search import SearchConfig, counterfactual_search
from sim import get_world
from sim.core import ABSENT, PRESENCE, PRESENT, SHIFTS
from sim.tabletop import tasks as TK

pytestmark = pytest.mark.slow
SEEDS = range(3)


@pytest.fixture(scope="module")
def world():
    return get_world("tabletop")


@pytest.fixture(scope="module")
def policy(world):
    return base_policy(world)


def _search(world, policy, task):
    demo = world.demonstrate(task)
    assert demo.success
    return counterfactual_search(
        world, policy, task.scene, demo, config=SearchConfig.for_world(world)
    )


def test_base_policy_solves_the_training_distribution(world, policy):
    tasks = [world.train_task(seed) for seed in range(10)]
    assert {TK._area_of(t.scene.obj("object")) for t in tasks} == set(TK.QUADRANTS)
    rollouts = world.rollout_batch(tasks, policy)
    assert sum(r.success for r in rollouts) >= 9
    picks = np.stack([r.actions[0, :2] for r in rollouts])  # (10, 2)
    assert np.ptp(picks, axis=0).min() > 0.3  # it looks where the object is, not one place


def test_a_failing_task_for_every_kind(world, policy):
    for shift in SHIFTS:
        task, rollout = failing_test_task(world, policy, shift, 0)
        assert task.shift == shift and not rollout.success
        assert world.demonstrate(task).success  # the task itself can be done


def test_tr_shifts_draw_the_same_scenes_as_ti_shifts(world):
    # so the searches below cover both: only R' (and so the feedback) differs
    for kind in ("object", "distractor"):
        for seed in range(20):
            ti, tr = world.test_task(f"{kind}_ti", seed), world.test_task(f"{kind}_tr", seed)
            assert ti.scene == tr.scene and ti.cause == tr.cause and ti.reward != tr.reward


def test_object_shift_finds_the_changed_concept(world, policy):
    for seed in SEEDS:
        task, _ = failing_test_task(world, policy, "object_ti", seed)
        result = _search(world, policy, task)
        assert result.found and result.size == 1, (seed, result.summary())
        changes = [next(iter(c.edit.changes)) for c in result.counterfactuals]
        assert all((c.slot, c.concept) == task.cause for c in changes), result.summary()
        train_value = TK.make_scene().obj(task.cause[0]).value(task.cause[1])
        assert result.best.edit.ordered[0].new == train_value  # the planted change, undone


def test_distractor_shift_finds_a_distractors_presence(world, policy):
    for seed in SEEDS:
        task, _ = failing_test_task(world, policy, "distractor_ti", seed)
        result = _search(world, policy, task)
        assert result.found, (seed, result.summary())
        best = result.best.edit.ordered
        assert all(
            c.slot in TK.DISTRACTORS and (c.concept, c.old, c.new) == (PRESENCE, PRESENT, ABSENT)
            for c in best
        ), result.summary()  # one distractor removed, or both where one is not enough


def test_other_shift_has_no_counterfactual(world, policy):
    seen = set()
    for seed in SEEDS:
        task, _ = failing_test_task(world, policy, "other", seed)
        seen.add(task.scene)
        result = _search(world, policy, task)
        assert not result.found and result.size is None
        assert {c.edit.size for c in result.tried} == {1, 2}  # every edit of up to 2 changes
    assert len(seen) == len(SEEDS)


def test_feedback_and_finetuning_raise_success_for_distractor_ti(world, policy, learns):
    """Measured with the committed base policy (4 seeds, shifted success; a budget of 10 and a
    third of the default finetuning steps keep the test short; object_ti below runs the
    defaults through `dfa run`): 0.10 -> 0.95."""
    pairs = []
    config = AdaptConfig(budget=10, finetuning=Finetuning(steps=100))
    for seed in range(4):
        task, _ = failing_test_task(world, policy, "distractor_ti", seed)
        record = run_loop(
            world, policy, task, SimulatedUser(world, seed=seed), config=config, seed=seed
        )
        assert record.failed and record.diagnosis.result.found
        assert all(not lab.relevant for lab in record.feedback.labels)
        assert record.adaptation.augmented
        pairs.append((record.evaluation.before.on_shift, record.evaluation.after.on_shift))
    learns(pairs, min_after=0.7, min_gain=0.4)


# -- `dfa run` end to end, with the recording read back ------------------------------------------
@pytest.fixture(scope="module")
def cli_run(tmp_path_factory, policy):
    out = tmp_path_factory.mktemp("tabletop")
    args = ["run", "--world", "tabletop", "--shift", "object_ti", "--seed", "0", "--json"]
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*args, "--out", str(out)]) == 0
    return json.loads(buf.getvalue())


def test_run_json_report_for_object_ti(cli_run):
    r = cli_run
    assert (r["world"], r["shift"], r["seed"]) == ("tabletop", "object_ti", 0)
    assert r["failed"] and r["counterfactual"]
    assert [f["label"] for f in r["feedback"]] == ["TI"]
    assert r["augmented"] > 0
    assert r["success_after"] - r["success_before"] >= 0.5  # 0.0 -> 1.0 measured


def _by_entity(path) -> dict[str, list[dict]]:
    store = rr.chunk.RrdReader(path).store()
    out: dict[str, list[dict]] = {}
    for chunk in store.stream():
        out.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch().to_pydict())
    return out


def _column(chunks: list[dict], name: str) -> list:
    return [v for c in chunks if name in c for v in c[name]]


def test_recording_holds_the_scene_in_3d(cli_run, world):
    chunks = _by_entity(cli_run["recording"])
    for rollout in ("failed", "demonstration", "counterfactual", "finetuned"):
        base = f"/scene3d/{rollout}"
        assert f"/rollouts/{rollout}/frame" in chunks
        assert _column(chunks[f"{base}/table"], "Boxes3D:half_sizes")
        for slot in ("object", "goal"):
            rows = chunks[f"{base}/{slot}"]
            mesh = _column(rows, "Mesh3D:vertex_positions")
            assert len(mesh) == 1 and len(mesh[0]) >= 12  # logged once, static
            assert _column(rows, "Mesh3D:triangle_indices")
            steps = _column(rows, "step")
            assert sorted(steps) == [0, 1]
            sim_time = [c for c in rows if "sim_time" in c]
            times = _column(sim_time, "sim_time")
            assert len(times) >= 2 and times == sorted(times)
            # the simulated carry ends where the rollout's step 1 is
            moves = np.array([v[0] for v in _column(sim_time, "Transform3D:translation")])
            at_step = {
                s: v[0]
                for c in rows
                if "step" in c
                for s, v in zip(c["step"], c["Transform3D:translation"], strict=True)
            }
            assert np.allclose(moves[-1], at_step[1], atol=1e-5)
            assert np.allclose(moves[0], at_step[0], atol=1e-5)
    # the demonstration carries the object: lifted above the table, then set down on the goal
    rows = chunks["/scene3d/demonstration/object"]
    moves = _column([c for c in rows if "sim_time" in c], "Transform3D:translation")
    assert len(moves) >= 10 and max(v[0][2] for v in moves) > 0.1
