"""DoorKey through the whole DFA loop: a base policy that solves its training distribution and
fails shifted tasks of every kind, the planted cause found, finetuning that helps, and
`dfa run --json` writing a recording that reads back with its frames lossless."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rerun as rr

from dfa_viz.cli import main
from dfa_viz.loop import run_loop
from dfa_viz.users import SimulatedUser
from policy import base_policy, failing_test_task
from search import SearchConfig, counterfactual_search, singles
from sim import get_world
from sim.core import ABSENT, PRESENCE, PRESENT, SHIFTS
from sim.doorkey.layout import LAVA_SLOTS, rows_of
from sim.doorkey.tasks import TRAIN_COLOURS

pytestmark = pytest.mark.slow
SEEDS = range(3)


@pytest.fixture(scope="module")
def world():
    return get_world("doorkey")


@pytest.fixture(scope="module")
def policy(world):
    return base_policy(world)


@pytest.fixture(scope="module")
def failing(world, policy):
    """(shift, seed) -> (task, failed rollout), each drawn once for the module."""
    found: dict[tuple[str, int], tuple] = {}

    def get(shift: str, seed: int):
        if (shift, seed) not in found:
            found[(shift, seed)] = failing_test_task(world, policy, shift, seed)
        return found[(shift, seed)]

    return get


def _search(world, policy, task, *, max_size: int = 2):
    demo = world.demonstrate(task)
    assert demo.success
    config = SearchConfig.for_world(world, max_size=max_size)
    return counterfactual_search(world, policy, task.scene, demo, config=config)


def test_base_policy_solves_the_training_distribution(world, policy):
    tasks = [world.train_task(seed) for seed in range(10)]
    assert len({rows_of(t.scene)["goal"] for t in tasks}) == 10
    rollouts = world.rollout_batch(tasks, policy)
    assert sum(r.success for r in rollouts) >= 9
    paths = {tuple(s.agent[:2] for s in r.scenes) for r in rollouts}
    assert len(paths) == 10  # it heads for where the goal is


def test_a_failing_task_for_every_kind(world, failing):
    for shift in SHIFTS:
        for seed in SEEDS:
            task, rollout = failing(shift, seed)
            assert task.shift == shift and not rollout.success
            assert world.demonstrate(task).success  # the task itself can be done


@pytest.mark.parametrize("shift", ["object_ti", "object_tr"])
def test_object_shift_finds_the_changed_colour(world, policy, failing, shift):
    for seed in SEEDS:
        task, _ = failing(shift, seed)
        result = _search(world, policy, task)
        assert result.found and result.size == 1, (seed, result.summary())
        (change,) = result.best.edit.ordered
        slot, concept = task.cause
        assert (change.slot, change.concept) == (slot, concept), result.summary()
        assert change.new == TRAIN_COLOURS[slot]  # the planted change, undone


@pytest.mark.parametrize("shift", ["distractor_ti", "distractor_tr"])
def test_distractor_shift_finds_a_lava_tiles_presence(world, policy, failing, shift):
    for seed in SEEDS:
        task, _ = failing(shift, seed)
        result = _search(world, policy, task)
        assert result.found, (seed, result.summary())
        for change in result.best.edit.ordered:
            assert change.slot in LAVA_SLOTS, result.summary()
            assert (change.concept, change.old, change.new) == (PRESENCE, PRESENT, ABSENT)
        if shift == "distractor_tr":  # the one lava tile there is, the one R' avoids
            assert [c.slot for c in result.best.edit.ordered] == ["lava0"]


def test_other_shift_has_no_counterfactual(world, policy, failing):
    for seed in SEEDS:
        task, _ = failing("other", seed)
        result = _search(world, policy, task)
        assert not result.found and result.tried, (seed, result.summary())
        assert {c.edit.size for c in result.tried} == {1, 2}


def test_size_one_search_tries_every_single_edit(world, policy, failing):
    """The whole size-1 search: every single edit once, rolled out in lockstep. How long it
    takes is `dfa bench`'s figure (the DoorKey size-1 search against its 0.5 s target, and the
    search against its forward-pass bound measured in the same run)."""
    for shift in ("object_ti", "distractor_ti"):
        task, _ = failing(shift, 0)
        demo = world.demonstrate(task)
        config = SearchConfig(max_size=1)
        result = counterfactual_search(world, policy, task.scene, demo, config=config)
        edits = singles(world.space, task.scene)
        assert len(result.tried) == len(edits) >= 12
        assert {c.edit for c in result.tried} == set(edits)
        assert result.found or shift == "distractor_ti"  # lava by the door: often two tiles


@pytest.mark.parametrize("shift", ["object_ti", "distractor_ti"])
def test_feedback_and_finetuning_raise_success(world, policy, failing, shift, learns):
    """Measured with the committed base policy (5 seeds, shifted success): object_ti
    0.08 -> 1.0, distractor_ti 0.04 -> 1.0."""
    pairs = []
    for seed in range(5):
        task, _ = failing(shift, seed)
        record = run_loop(world, policy, task, SimulatedUser(world, seed=seed), seed=seed)
        assert record.failed and record.diagnosis.result.found
        labels = record.feedback.labels
        assert labels and not any(lab.relevant for lab in labels)
        assert record.adaptation.augmented
        pairs.append((record.evaluation.before.on_shift, record.evaluation.after.on_shift))
    learns(pairs, min_after=0.85, min_gain=0.5)


def _chunks(path):
    by_entity: dict[str, list[dict]] = {}
    for chunk in rr.chunk.RrdReader(path).store().stream():
        by_entity.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch().to_pydict())
    return by_entity


def test_dfa_run_json_writes_a_lossless_recording(world, policy, failing, tmp_path, capsys):
    argv = ["run", "--world", "doorkey", "--shift", "object_ti", "--seed", "0", "--json"]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["world"], report["shift"], report["seed"]) == ("doorkey", "object_ti", 0)
    task, rollout = failing("object_ti", 0)
    (change,) = report["counterfactual"][0]
    assert (change["slot"], change["concept"]) == task.cause
    assert report["success_after"] - report["success_before"] >= 0.5  # 0.0 -> 1.0 measured

    path = tmp_path / "doorkey-object_ti-seed0.rrd"
    assert report["recording"] == str(path)
    store = rr.chunk.RrdReader(path).store()
    summary = store.summary()
    for name in ("failed", "demonstration", "counterfactual"):
        lines = [ln for ln in summary.splitlines() if ln.startswith(f"/rollouts/{name}/frame ")]
        assert lines and all("Image:buffer" in ln for ln in lines), name
        assert not any("EncodedImage" in ln for ln in lines), name
    chunks = _chunks(path)
    cands = sorted(e for e in chunks if e.startswith("/search/candidates/c"))
    assert len(cands) == report["candidates_tried"] > 0
    # the failed rollout's frames are stored bit for bit
    rows = sorted(
        (step, buf)
        for c in chunks["/rollouts/failed/frame"]
        for step, buf in zip(c["step"], c["Image:buffer"], strict=True)
    )
    assert [s for s, _ in rows] == list(range(world.horizon + 1))
    frames = np.stack([np.asarray(b[0] if len(b) == 1 else b, np.uint8) for _, b in rows])
    assert np.array_equal(frames.reshape(rollout.observations.shape), rollout.observations)
