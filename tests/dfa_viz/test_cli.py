import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from scipy.stats import binomtest

from dfa_viz.cli import main

pytestmark = pytest.mark.slow
DFA = [sys.executable, "-m", "dfa_viz.cli"]


def dfa(*args, cwd=None):
    return subprocess.run([*DFA, *args], capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def run_json(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    proc = dfa(
        "run",
        "--world",
        "nav2d",
        "--shift",
        "object_ti",
        "--seed",
        "0",
        "--json",
        "--out",
        str(out),
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_json_report_has_the_promised_fields(run_json):
    r = run_json
    for key in (
        "world",
        "shift",
        "seed",
        "counterfactual",
        "feedback",
        "success_before",
        "success_after",
        "recording",
    ):
        assert key in r
    assert (r["world"], r["shift"], r["seed"]) == ("nav2d", "object_ti", 0)
    change = r["counterfactual"][0][0]
    assert set(change) == {"slot", "concept", "from", "to"} and change["slot"] == "goal"
    assert r["feedback"][0]["label"] == "TI"
    # 0.3 -> 0.4 measured on held-out layouts and values (7 distinct)
    assert r["success_after"] > r["success_before"]
    # the same tasks before and after, paired over their distinct scenes
    for key, distinct in (("on_shift", "distinct_scenes"), ("all", "distinct_scenes_all")):
        ch = r["change"][key]
        assert ch["units"] == r["fresh"][distinct] and ch["fixed"] + ch["broken"] <= ch["units"]
        assert ch["p"] == pytest.approx(
            binomtest(ch["fixed"], ch["fixed"] + ch["broken"], 0.5, alternative="greater").pvalue
            if ch["fixed"] + ch["broken"]
            else 1.0
        )


def _chunks(path):
    store = rr.chunk.RrdReader(path).store()
    by_entity = {}
    for chunk in store.stream():
        by_entity.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch().to_pydict())
    return by_entity


def test_recording_reads_back_with_rerun(run_json, nav, nav_policy):
    path = Path(run_json["recording"])
    chunks = _chunks(path)
    for entity in (
        "/rollouts/failed/frame",
        "/rollouts/demonstration/frame",
        "/rollouts/counterfactual/frame",
        "/rollouts/finetuned/frame",
        "/action_distance/failed",
        "/action_distance/counterfactual",
        "/rollouts/failed/action/0",
        "/rollouts/failed/success",
        "/augmented/a000/frame",
        "/charts/loss",
        "/charts/success",
        "/task",
        "/edit/delta",
        "/feedback",
        "/finetune/loss",
        "/evaluation/success",
    ):
        assert entity in chunks, entity
    frames = chunks["/rollouts/failed/frame"]
    assert sum(len(c["step"]) for c in frames) == 21
    assert any(k.startswith("Image:") for k in frames[0])  # lossless, not EncodedImage
    # every candidate the search tried is there, with its distance trace
    cands = sorted(e for e in chunks if e.startswith("/search/candidates/c"))
    assert len(cands) == run_json["candidates_tried"]
    # the counterfactual's action distances are the real ones, recomputed here
    from policy import failing_test_task

    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    ch = run_json["counterfactual"][0][0]
    from sim.core import Change, Edit

    edited = nav.apply(task.scene, Edit.of(Change(ch["slot"], ch["concept"], ch["from"], ch["to"])))
    roll = nav.rollout(task, nav_policy, scene=edited)
    want = np.abs(roll.actions - demo.actions).sum(axis=1)
    rows = chunks["/action_distance/counterfactual"][0]
    got = np.array([v[0] for v in rows["Scalars:scalars"]])
    assert rows["step"] == list(range(20))
    assert np.allclose(got, want, atol=1e-6)
    bound = run_json["search_epsilon"]  # the world's, or less (search.counterfactual.bound)
    assert 0 < bound <= nav.epsilon and (got < bound).all()
    # the failed rollout's distance too: it reaches the bound at some step (that is the failure
    # the search tells apart). Here it misses the goal by drifting, never straying the world's
    # 0.2 a step, so the counterfactual was held under the failure's own largest distance
    failed = nav.rollout(task, nav_policy)
    rows = chunks["/action_distance/failed"][0]
    got = np.array([v[0] for v in rows["Scalars:scalars"]])
    steps = min(len(failed.actions), len(demo.actions))
    assert np.allclose(got, np.abs(failed.actions[:steps] - demo.actions[:steps]).sum(axis=1))
    assert got.max() == pytest.approx(bound, abs=1e-6) and bound < nav.epsilon
    # the recording draws that bound beside ε and says why in the edit's panel
    line = np.array([v[0] for v in chunks["/action_distance/bound"][0]["Scalars:scalars"]])
    assert np.allclose(line, bound) and len(line) == 20
    text = str(chunks["/edit/delta"][0])
    assert "failed rollout never strayed 0.2 a step" in text
    # a reviewer sees what the recording is without us
    assert chunks["/__properties"][0]["RecordingInfo:name"] == [["nav2d · object_ti · seed 0"]]
    props = chunks["/__properties/task"][0]
    assert (props["world"], props["shift"], props["seed"]) == ([["nav2d"]], [["object_ti"]], [[0]])


def test_same_seed_writes_the_same_recording(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert (
            main(
                [
                    "run",
                    "--world",
                    "nav2d",
                    "--shift",
                    "distractor_ti",
                    "--seed",
                    "1",
                    "--json",
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
    ra, rb = (
        _chunks(a / "nav2d-distractor_ti-seed1.rrd"),
        _chunks(b / "nav2d-distractor_ti-seed1.rrd"),
    )
    assert ra.keys() == rb.keys()
    for key in ra:
        assert _rows(ra[key]) == _rows(rb[key]), key


def _rows(chunks):
    """Every row of an entity as a tuple of its columns (chunk boundaries may differ)."""
    rows = []
    for c in chunks:
        cols = sorted(k for k in c if "RowId" not in k)
        rows += [tuple(repr(c[k][i]) for k in cols) for i in range(len(c[cols[0]]))]
    return sorted(rows)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "--world", "mars"], "unknown world 'mars'; accepted: nav2d"),
        (["run", "--shift", "sideways"], "unknown shift 'sideways'; accepted: object_ti"),
        (
            ["run", "--label", "goal.size=TI"],
            "unknown concept 'size' for slot 'goal'; accepted: colour, shape",
        ),
        (["run", "--label", "goal.colour=maybe"], "the answer is TI or TR"),
    ],
)
def test_bad_input_gives_one_clear_line(args, message):
    proc = dfa(*args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in proc.stderr


def one_line_error(capsys, *args: str) -> str:
    """Run `dfa ARGS` in this process: it must exit 2 with one line on stderr; returns it."""
    assert main(list(args)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dfa: error: "), err
    return err[0]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seed", "-1"], "seed must be an integer from 0 to 2147483647, not -1"),
        (["--seed", "18446744073709551616"], "seed must be an integer from 0 to 2147483647"),
        (["--max-size", "0"], "--max-size must be from 1 to 3 concept changes, not 0"),
        (["--accuracy", "1.5"], "accuracy is a probability in [0, 1], not 1.5"),
        (
            ["--label", "goal.colour=TI", "--label", "goal.colour=TR"],
            "--label goal.colour is given both TI and TR; give one answer",
        ),
    ],
)
def test_bad_run_options_are_one_line(capsys, args, message):
    assert message in one_line_error(capsys, "run", *args)


def test_out_naming_a_file_is_refused(capsys, tmp_path):
    (tmp_path / "f").write_text("keep")
    line = one_line_error(capsys, "run", "--out", str(tmp_path / "f"))
    assert "is a file; give a folder for the outputs" in line
    assert (tmp_path / "f").read_text() == "keep"


@pytest.mark.parametrize(
    "command",
    [
        ["run"],
        ["bench"],
        ["prior"],
        ["serve"],
        ["demo"],
        ["sweep"],
        ["experiment", "q2"],
        ["experiment", "explain"],
        ["study", "new"],
    ],
)
def test_every_output_under_a_file_is_refused_before_any_work(capsys, tmp_path, command):
    """Every subcommand that writes checks where it writes first: a path under a file is one
    line at once (not after a 38 s fit), and the file is untouched."""
    (tmp_path / "f").write_text("keep")
    line = one_line_error(capsys, *command, "--out", str(tmp_path / "f" / "x.json"))
    assert f"{tmp_path / 'f'} is a file, so nothing can be written under it" in line
    assert (tmp_path / "f").read_text() == "keep"


@pytest.mark.parametrize("command", [["run"], ["serve"], ["experiment", "q2"]])
def test_painted_replay_in_a_world_of_named_colours_is_one_line(capsys, tmp_path, command):
    out = tmp_path / "out"
    args = ["--world", "nav2d", "--replay-looks", "painted", "--out", str(out)]
    line = one_line_error(capsys, *command, *args)
    assert "--replay-looks painted needs a world that draws any colour" in line
    assert "nav2d draws only its named colours: training or varied" in line
    assert not out.exists()


def test_malformed_demo_files(capsys, tmp_path, nav, nav_policy):
    from policy import failing_test_task

    bad = tmp_path / "demo.npz"
    bad.write_bytes(b"garbage")
    assert "demo.npz: not an .npz archive" in one_line_error(capsys, "run", "--demo", str(bad))
    npy = tmp_path / "array.npz"
    with open(npy, "wb") as f:
        np.save(f, np.zeros((21, 2)))
    assert "array.npz: not an .npz archive" in one_line_error(capsys, "run", "--demo", str(npy))
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    small = dataclasses.replace(
        demo, observations=np.ascontiguousarray(demo.observations[:, ::2, ::2])
    )
    path = small.save(tmp_path / "small.npz")
    line = one_line_error(capsys, "run", "--demo", str(path))
    assert "frames of shape (18, 18, 3), but nav2d renders (36, 36, 3)" in line
    nan = demo.actions.copy()
    nan[3, 0] = np.nan
    path = dataclasses.replace(demo, actions=nan).save(tmp_path / "nan.npz")
    line = one_line_error(capsys, "run", "--demo", str(path))
    assert "the action at step 3 is not a finite number" in line
    ints = dataclasses.replace(demo, actions=demo.actions.astype(np.int64)).save(tmp_path / "i.npz")
    assert "nav2d needs float actions" in one_line_error(capsys, "run", "--demo", str(ints))
    # one waypoint short of the goal: a demonstration that does not do what the task asks
    miss = dataclasses.replace(demo, actions=demo.actions * 0.5).save(tmp_path / "miss.npz")
    line = one_line_error(capsys, "run", "--demo", str(miss))
    assert "does not succeed at what the task asks" in line


def test_malformed_checkpoints(capsys, tmp_path):
    ckpt = tmp_path / "ckpt"
    ckpt.mkdir()
    (ckpt / "config.json").write_text(
        json.dumps(
            {
                "policy": {
                    "world": "nav2d",
                    "obs_shape": [36, 36, 3],
                    "action_dim": 2,
                    "discrete": False,
                }
            }
        )
    )
    from safetensors.numpy import save_file

    save_file({"x": np.zeros(3, np.float32)}, str(ckpt / "model.safetensors"))
    line = one_line_error(capsys, "run", "--policy", str(ckpt))
    assert "do not match the architecture" in line
    (ckpt / "config.json").write_text('{"policy": {"world": "nav2d", "hidden": -5}}')
    assert "obs_shape must be a list of 3 integers" in one_line_error(
        capsys, "run", "--policy", str(ckpt)
    )


def test_a_failed_run_leaves_the_earlier_recording(capsys, tmp_path):
    args = ["run", "--shift", "object_ti", "--seed", "0", "--json", "--out", str(tmp_path)]
    assert main(args) == 0
    capsys.readouterr()
    path = tmp_path / "nav2d-object_ti-seed0.rrd"
    before = path.read_bytes()
    # the search runs, then the label names a concept the edit does not change: an error
    line = one_line_error(capsys, *args, "--label", "distractor.presence=TI")
    assert "--label distractor.presence: the counterfactual edit changes goal." in line
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no partial files


def test_json_output_is_strict_json(run_json):
    def no_constants(name):
        raise AssertionError(f"{name} is not JSON")

    json.loads(json.dumps(run_json), parse_constant=no_constants)


def test_a_given_demonstration_is_used(tmp_path, nav, nav_policy):
    from policy import failing_test_task

    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    path = nav.demonstrate(task).save(tmp_path / "demo.npz")
    proc = dfa(
        "run", "--shift", "distractor_ti", "--demo", str(path), "--json", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["counterfactual"][0][0]["concept"] == "presence"
    wrong = nav.demonstrate(nav.train_task()).save(tmp_path / "wrong.npz")
    proc = dfa("run", "--shift", "distractor_ti", "--demo", str(wrong))
    assert proc.returncode == 2 and "starts from another scene" in proc.stderr


def test_prior_command_writes_a_prior_that_run_checks(capsys, tmp_path):
    from search.prior import LearnedPrior
    from sim import get_world

    path = tmp_path / "doorkey.json"
    assert main(["prior", "--world", "doorkey", "--tasks", "2", "--out", str(path)]) == 0
    assert f"written to {path}" in capsys.readouterr().out
    assert LearnedPrior.load(path, get_world("doorkey")).world == "doorkey"
    line = one_line_error(capsys, "run", "--world", "nav2d", "--prior", str(path))
    assert "the learned prior is for world 'doorkey', not 'nav2d'" in line
    assert "no learned prior at" in one_line_error(capsys, "run", "--prior", str(tmp_path / "no"))
    (tmp_path / "bad.json").write_text('{"format": "something else"}')
    line = one_line_error(capsys, "run", "--prior", str(tmp_path / "bad.json"))
    assert "malformed learned prior" in line
    (tmp_path / "cut.json").write_text(path.read_text()[:40])
    assert "cannot read learned prior" in one_line_error(
        capsys, "run", "--prior", str(tmp_path / "cut.json")
    )
    line = one_line_error(capsys, "prior", "--tasks", "0", "--out", str(tmp_path / "p.json"))
    assert "--tasks must be at least 1" in line
