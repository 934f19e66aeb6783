"""`dfa run --lerobot DIR` on nav2d: the run's trajectories read back from the dataset as they
were (frames bit-exact, actions, dfa's columns), the variants read back finetuning the base
policy to the same success as the run's own, an exported demonstration replayed by
`--demo lerobot:DIR:episode=N` (a changed one refused at its first differing step), every
episode in one recording with `dfa view`, and bad input refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rerun as rr

from dfa_viz.assemble import run_once
from dfa_viz.cli import main
from dfa_viz.configs import AdaptConfig, Finetuning, RunArgs
from dfa_viz.loop import adapt, evaluate
from policy import base_policy, training_demos
from policy.train import transitions
from policy.variants import fill_budget
from sim.core import Scene
from sim.lerobot import Dataset, Episode, write_dataset
from sim.lerobot.demo import trajectory

pytestmark = pytest.mark.slow
TINY = ["--budget", "3", "--steps", "10", "--n-eval", "2", "--max-size", "1"]
CONFIG = AdaptConfig(budget=3, finetuning=Finetuning(steps=10, n_eval=2))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One run of the loop, in this process, written as a recording and a dataset."""
    tmp = tmp_path_factory.mktemp("run")
    args = RunArgs(
        world="nav2d",
        shift="object_ti",
        seed=0,
        max_size=1,
        out=tmp / "rec",
        lerobot=tmp / "ds",
        adapt=CONFIG,
    )
    record = run_once(args, progress=False)
    assert record.dataset == str(tmp / "ds")
    return record, tmp / "ds"


def _trajectories(record):
    """What the run holds, in the dataset's order: the demonstration, the variants, the
    counterfactuals (the one shown first), the failed and the finetuned rollouts."""
    d = record.diagnosis
    order = [d.tie, *(i for i in range(len(d.counterfactuals)) if i != d.tie)]
    return [
        ("demonstration", record.demo, None),
        *(("variant", v, None) for v in record.adaptation.augmented),
        *(
            ("counterfactual", d.counterfactuals[i], d.result.counterfactuals[i].edit)
            for i in order
        ),
        ("failed", record.rollout, None),
        ("finetuned", record.adaptation.rollout, None),
    ]


def test_the_run_reads_back_as_it_was(run, nav):
    record, root = run
    ds = Dataset(root)
    want = _trajectories(record)
    assert len(ds) == len(want) and ds.robot_type == "nav2d"
    assert ds.features["observation.images.main"]["dtype"] == "image"  # 36x36: lossless
    assert json.loads((root / "meta/info.json").read_text())["total_frames"] == sum(
        t.horizon for _, t, _ in want
    )
    demo = record.demo
    for i, (role, traj, edit) in enumerate(want):
        ep = ds.episode(i)
        t = traj.horizon
        assert ep.text("dfa.role") == role, i
        assert ep.task == record.task.reward.instruction
        assert np.array_equal(ep.frames, traj.observations[:t])  # bit-exact
        assert np.array_equal(ep.actions, traj.actions)
        assert ep.success == bool(traj.success)
        scenes = [Scene.from_dict(json.loads(s)) for s in ep.columns["dfa.scene"]]
        assert scenes == list(traj.scenes[:t])
        assert set(ep.columns["dfa.run"]) == {"nav2d object_ti seed 0"}
        distance = ep.columns["dfa.action_distance"]
        if role in ("counterfactual", "failed", "finetuned"):
            assert np.allclose(distance, np.abs(traj.actions - demo.actions).sum(axis=1))
        else:
            assert not distance.any()
        if role == "counterfactual":
            assert ep.text("dfa.edit") == str(edit)
            assert ep.text("dfa.concept") == "goal.shape"
            assert ep.text("dfa.label") == "TI"  # the simulated user's mark
        if role == "variant" and ep.text("dfa.edit"):
            assert set(ep.text("dfa.concept").split()) <= {"goal.shape"}  # the TI concept
    roles = [ds.episode(i).text("dfa.role") for i in range(len(ds))]
    assert roles.count("variant") == 2 and roles.count("counterfactual") >= 1
    assert [ds.episode(i).success for i in range(len(ds))][-2:] == [False, True]


def test_the_variants_read_back_finetune_to_the_same_success(run, nav):
    record, root = run
    ds = Dataset(root)
    read = [ds.episode(i) for i in range(len(ds))]
    back = [
        trajectory(nav, ep, source=f"episode {i}")
        for i, ep in enumerate(read)
        if ep.text("dfa.role") in ("demonstration", "variant")
    ]
    demo, variants = back[0], back[1:]
    ad = record.adaptation
    known = training_demos(nav)
    # the transitions finetuned on are the same, pixel for pixel
    for a, b in zip(
        transitions(nav, fill_budget(record.demo, ad.augmented, CONFIG.budget)),
        transitions(nav, fill_budget(demo, variants, CONFIG.budget)),
        strict=True,
    ):
        assert np.array_equal(a, b)
    base = base_policy(nav)
    again = adapt(
        nav,
        base,
        record.task,
        demo,
        record.feedback,
        config=CONFIG,
        seed=0,
        known=known,
        augmented=variants,
    )
    assert np.array_equal(again.rollout.actions, ad.rollout.actions)
    ev = evaluate(nav, base, again.policy, record.task, n=CONFIG.finetuning.n_eval, seed=0)
    assert ev.after == record.evaluation.after
    assert ev.before == record.evaluation.before


def _dfa(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_an_exported_demonstration_is_replayed_by_run(run, tmp_path, capsys):
    record, root = run
    code, out, err = _dfa(
        capsys,
        "run",
        "--world", "nav2d", "--shift", "object_ti", "--seed", "0", "--json", *TINY,
        "--demo", f"lerobot:{root}:episode=0",
        "--out", str(tmp_path),
    )  # fmt: skip
    assert code == 0, err
    report = json.loads(out)
    # the expert's demonstration, replayed from the dataset, makes the very same run
    same = {k: v for k, v in record.to_json().items() if k not in ("recording", "dataset")}
    assert {k: report[k] for k in same} == same
    assert report["dataset"] is None


def test_a_changed_demonstration_is_refused_at_its_first_differing_step(run, tmp_path, capsys):
    _, root = run
    ep = Dataset(root).episode(0)
    actions = ep.actions.copy()
    actions[6] += np.float32(0.6)
    changed = Episode(ep.task, ep.frames, actions, ep.success, ep.columns)
    write_dataset(tmp_path / "changed", [changed], fps=10, robot_type="nav2d", video=False)
    code, out, err = _dfa(
        capsys,
        "run", "--world", "nav2d", "--shift", "object_ti", "--seed", "0", *TINY,
        "--demo", f"lerobot:{tmp_path / 'changed'}", "--out", str(tmp_path / "rec"),
    )  # fmt: skip
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("dfa: error: ")
    assert "episode 0: frame 7 is not what nav2d shows after actions 0 to 6" in err
    assert not (tmp_path / "rec").exists()  # refused before anything was written


def test_view_writes_every_episode_into_one_recording(run, tmp_path, capsys):
    _, root = run
    path = tmp_path / "view.rrd"
    code, out, err = _dfa(capsys, "view", str(root), "--out", str(path))
    assert code == 0, err
    ds = Dataset(root)
    assert f"{len(ds)} episodes" in out
    store = rr.chunk.RrdReader(path).store()
    chunks: dict[str, list] = {}
    for chunk in store.stream():
        chunks.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch().to_pydict())
    for i in range(len(ds)):
        ep = ds.episode(i)
        frames = chunks[f"/episodes/e{i:03d}/frame"]
        steps = sorted(s for c in frames for s in c["step"])
        assert steps == list(range(ep.length))
        first = next(c for c in frames if 0 in c["step"])
        k = first["step"].index(0)
        pixels = np.asarray(first["Image:buffer"][k][0], dtype=np.uint8)
        assert np.array_equal(pixels.reshape(ep.frames[0].shape), ep.frames[0])  # lossless
        for d in range(2):
            rows = chunks[f"/actions/{d}/e{i:03d}"]
            got = [v[0] for c in rows if "Scalars:scalars" in c for v in c["Scalars:scalars"]]
            assert np.allclose(got, ep.actions[:, d])
        info = chunks[f"/episodes/e{i:03d}/info"][0]["TextDocument:text"][0][0]
        assert ep.text("dfa.role") in info and ep.task in info


def test_bad_input_is_one_line(run, tmp_path, capsys):
    _, root = run
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "notes.txt").write_text("mine")
    (tmp_path / "plain").mkdir()
    cases = [
        (("view", str(tmp_path / "missing")), "not a LeRobot dataset (no such folder)"),
        (("view", str(tmp_path / "plain")), "not a LeRobot dataset (no meta/info.json)"),
        (("view", str(root), "--episodes", "99"), "no episode 99; it has episodes 0 to"),
        (
            ("run", "--world", "nav2d", "--demo", f"lerobot:{root}:episode=99", *TINY),
            "no episode 99; it has episodes 0 to",
        ),
        (
            ("run", "--world", "nav2d", "--demo", f"lerobot:{tmp_path / 'plain'}", *TINY),
            "not a LeRobot dataset (no meta/info.json)",
        ),
        (
            ("run", "--world", "nav2d", *TINY, "--lerobot", str(occupied)),
            "holds files and is not a LeRobot dataset",
        ),
        (
            (
                "export",
                "lerobot",
                "--from",
                str(tmp_path / "missing"),
                "--out",
                str(tmp_path / "x"),
            ),
            "no such folder",
        ),
        (
            ("run", "--world", "nav2d", *TINY, "--lerobot", str(occupied / "notes.txt" / "ds")),
            "notes.txt is a file, so nothing can be written under it",
        ),
        (
            ("export", "lerobot", "--from", str(tmp_path / "plain"), "--out", str(tmp_path / "x")),
            "holds none of session.jsonl, sweep.csv, runs.csv",
        ),
        (
            ("export", "lerobot", "--from", str(root), "--out", str(occupied)),
            "holds files and is not a LeRobot dataset",
        ),
    ]
    for argv, message in cases:
        extra = ("--out", str(tmp_path / "r")) if argv[0] == "run" else ()
        code, _, err = _dfa(capsys, *argv, *extra)
        assert code == 2, (argv, err)
        assert err.count("\n") == 1 and err.startswith("dfa: error: "), (argv, err)
        assert message in err, (argv, err)
    assert [p.name for p in occupied.iterdir()] == ["notes.txt"]
    assert not (tmp_path / "r").exists() and not (tmp_path / "x").exists()
