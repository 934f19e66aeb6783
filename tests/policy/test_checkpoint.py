"""Checkpoints from outside: every malformed config or weights file is one line, checked
before anything is built; the committed base policies of record load and match their recipe."""

from __future__ import annotations

import dataclasses
import json
import shutil

import pytest
import torch
from safetensors.torch import load_file, save_file

from policy import base as B
from policy import load_policy, save_policy
from policy.model import ImagePolicy, Policy, PolicyConfig
from policy.train import training_demos
from sim import PAPER_WORLDS, get_world
from sim.core import UserError


@pytest.fixture
def ckpt(nav, tmp_path):
    """A valid nav2d checkpoint folder (a small untrained net) to break in each test; its
    config.json records no weights digest, as a checkpoint made by hand would not."""
    small = Policy(ImagePolicy(PolicyConfig("nav2d", (36, 36, 3), 2, False, hidden=50)))
    folder = save_policy(small, tmp_path / "ckpt")
    doc = json.loads((folder / "config.json").read_text())
    del doc["weights_sha256"]
    (folder / "config.json").write_text(json.dumps(doc))
    return folder


def _set(folder, **fields):
    doc = json.loads((folder / "config.json").read_text())
    doc["policy"].update(fields)
    (folder / "config.json").write_text(json.dumps(doc))


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (b"[1, 2, 3]", 'expected a JSON object with a "policy" object'),
        (b'{"policy": [36, 36, 3]}', 'expected a JSON object with a "policy" object'),
        (b"\xff\xfe{not utf-8", "config.json: not UTF-8 text; expected a JSON object"),
        (b"{" * 100_000, "config.json: not valid JSON"),
    ],
)
def test_a_config_that_is_not_a_json_object_is_refused(nav, ckpt, raw, message):
    (ckpt / "config.json").write_bytes(raw)
    with pytest.raises(UserError, match=message):
        load_policy(ckpt, world=nav)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"obs_shape": "abc"}, 'obs_shape must be a list of 3 integers from 1 to 1024, not "abc"'),
        ({"obs_shape": [4, 4, 3]}, r"obs_shape \[4, 4, 3\] does not fit nav2d"),
        ({"hidden": -5}, "hidden must be an integer from 1 to 4096, not -5"),
        ({"hidden": 10**9}, "hidden must be an integer from 1 to 4096"),
        ({"channels": [32, 64, 100000]}, "channels must be a list of 3 integers from 1 to 256"),
        ({"discrete": True}, "discrete=true, action_dim=2 does not fit nav2d"),
        ({"action_dim": 3}, "action_dim=3 does not fit nav2d"),
        ({"world": "doorkey"}, "is for world \"doorkey\", not 'nav2d'"),
        ({"kernels": [16, 16, 16]}, "do not fit 36x36 observations"),
        ({"colour": "red"}, r"unknown fields \['colour'\]"),
    ],
)
def test_config_values_are_checked_before_anything_is_built(nav, ckpt, fields, message):
    _set(ckpt, **fields)
    with pytest.raises(UserError, match=message) as err:
        load_policy(ckpt, world=nav)
    assert "\n" not in str(err.value)


def test_weights_of_another_world_are_refused(nav, ckpt):
    table = get_world("tabletop")
    shutil.copy(B.WEIGHTS / "tabletop" / "model.safetensors", ckpt / "model.safetensors")
    _set(ckpt, hidden=100)
    with pytest.raises(UserError, match=r"has shape \(100, \d+\), expected \(100, \d+\)"):
        load_policy(ckpt, world=nav)
    # tabletop's own config, relabelled nav2d
    shutil.copy(B.WEIGHTS / "tabletop" / "config.json", ckpt / "config.json")
    _set(ckpt, world="nav2d")
    with pytest.raises(UserError, match=r"obs_shape \[80, 80, 3\] does not fit nav2d"):
        load_policy(ckpt, world=nav)
    assert load_policy(B.WEIGHTS / "tabletop", world=table) is not None


def test_non_finite_weights_are_refused(nav, ckpt):
    state = load_file(ckpt / "model.safetensors")
    state["head.0.bias"][3] = float("nan")
    save_file(state, str(ckpt / "model.safetensors"))
    with pytest.raises(UserError, match=r"tensor head.0.bias has 1 non-finite values"):
        load_policy(ckpt, world=nav)


def test_missing_files_and_folders(nav, ckpt, tmp_path):
    with pytest.raises(UserError, match="not a folder"):
        load_policy(tmp_path / "nowhere", world=nav)
    (ckpt / "config.json").unlink()
    with pytest.raises(UserError, match=r"missing config\.json"):
        load_policy(ckpt, world=nav)
    (ckpt / "model.safetensors").write_bytes(b"garbage")
    _set_file = ckpt / "config.json"
    _set_file.write_text(
        json.dumps({"policy": PolicyConfig("nav2d", (36, 36, 3), 2, False).to_dict()})
    )
    with pytest.raises(UserError, match="not a readable safetensors file"):
        load_policy(ckpt, world=nav)


@pytest.mark.parametrize("name", PAPER_WORLDS)
def test_committed_base_policies_match_todays_recipe(name):
    """The weights of record are in the repository, with the recipe they were trained from;
    loading them checks that recipe against today's (no retraining, on any machine)."""
    world = get_world(name)
    folder = B.WEIGHTS / name
    meta = json.loads((folder / "config.json").read_text())["meta"]
    assert meta["command"] == f"dfa train --retrain --worlds {name}"
    n = world.cloning.demonstrations
    assert meta["training_tasks_solved"] == f"{n}/{n}"
    policy = B.base_policy(world)
    stored = load_file(folder / "model.safetensors")
    for key, value in policy.net.state_dict().items():
        assert torch.equal(value, stored[key]), key


def test_a_changed_recipe_with_stale_weights_is_an_error(nav, tmp_path, monkeypatch):
    shutil.copytree(B.WEIGHTS / "nav2d", tmp_path / "nav2d")
    doc = json.loads((tmp_path / "nav2d" / "config.json").read_text())
    doc["meta"]["recipe"]["train"]["steps"] = 999
    (tmp_path / "nav2d" / "config.json").write_text(json.dumps(doc))
    monkeypatch.setattr(B, "WEIGHTS", tmp_path)
    with pytest.raises(UserError) as err:
        B.base_policy(nav)
    message = str(err.value)
    assert "trained with another recipe (train.steps: 999 then, 840 now)" in message
    assert "dfa train --retrain --worlds nav2d" in message
    doc["meta"]["recipe"] = {
        **doc["meta"]["recipe"],
        "train": B.recipe(nav, [], seed=0, config=B.base_config(nav))["train"],
    }
    doc["meta"]["recipe"]["frame_colours"][0] = [0.0, 0.0, 0.0]
    (tmp_path / "nav2d" / "config.json").write_text(json.dumps(doc))
    with pytest.raises(UserError, match="the training frames look different"):
        B.base_policy(nav)


@pytest.mark.parametrize("name", PAPER_WORLDS)
def test_committed_weights_are_checked_against_their_recorded_digest(name, tmp_path):
    """config.json records the sha256 of model.safetensors; one flipped bit is refused."""
    doc = json.loads((B.WEIGHTS / name / "config.json").read_text())
    assert len(doc["weights_sha256"]) == 64
    copy = shutil.copytree(B.WEIGHTS / name, tmp_path / name)
    raw = bytearray((copy / "model.safetensors").read_bytes())
    raw[-7] ^= 0x01  # a bit of the last tensor's values: still a readable safetensors file
    (copy / "model.safetensors").write_bytes(bytes(raw))
    with pytest.raises(UserError, match=r"is not the file config\.json recorded") as err:
        load_policy(copy, world=get_world(name))
    assert "\n" not in str(err.value)


def test_a_damaged_cached_base_policy_is_trained_again_with_one_line(
    nav, tmp_path, monkeypatch, capsys
):
    """A base policy cached outside the repository (seed 1 here) whose weights no longer match
    their digest is dropped and trained again; the user is told in one line."""
    monkeypatch.setenv("DFA_CACHE", str(tmp_path))
    first = B.base_policy(nav, seed=1)
    folder = B.base_folder(nav, seed=1)
    assert folder.is_relative_to(tmp_path)
    raw = bytearray((folder / "model.safetensors").read_bytes())
    raw[-7] ^= 0x01
    (folder / "model.safetensors").write_bytes(bytes(raw))
    capsys.readouterr()
    again = B.base_policy(nav, seed=1)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the cached base policy is unusable" in err[0], err
    assert "training it again" in err[0]
    load_policy(folder, world=nav)  # its digest holds again
    frames = nav.render_batch([nav.sample_scene(s) for s in range(4)])
    assert again.outputs(frames).shape == first.outputs(frames).shape


EVIL = """
from pathlib import Path
Path(__file__).with_name("IMPORTED").write_text("the module ran")
def make():
    Path(__file__).with_name("CALLED").write_text("the callable ran")
"""


def _named_code(folder, tmp_path, monkeypatch):
    """A checkpoint whose config.json names a module that leaves a mark when imported."""
    (tmp_path / "code_here.py").write_text(EVIL)
    monkeypatch.syspath_prepend(str(tmp_path))
    doc = json.loads((folder / "config.json").read_text())
    doc.pop("policy")
    doc["source"] = f"torch:code_here:make@{folder / 'model.safetensors'}"
    (folder / "config.json").write_text(json.dumps(doc))
    return folder


def test_a_checkpoint_that_names_code_never_runs_it(nav, ckpt, tmp_path, monkeypatch, capsys):
    """Only the command line may name a module: a folder's "source" is not followed, by `dfa
    run --policy`, nor by a page session resuming a finetuned policy it saved."""
    from dfa_viz.app.sessions import Session, SessionError
    from dfa_viz.cli import main

    folder = _named_code(ckpt, tmp_path, monkeypatch)
    assert main(["run", "--policy", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "which dfa does not follow" in err[0], err
    session = Session.new(tmp_path / "sessions", world="nav2d")
    try:
        shutil.copytree(folder, session.folder / "policy-0001")
        with pytest.raises(SessionError, match="which dfa does not follow"):
            session.load_policy("policy-0001", nav, base=B.base_policy(nav))
    finally:
        session.close()
    assert not (tmp_path / "IMPORTED").exists() and not (tmp_path / "CALLED").exists()


def test_weights_without_the_policy_they_were_finetuned_from_are_one_line(capsys, tmp_path):
    from dfa_viz.cli import main

    assert main(["run", "--weights", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "finetuned weights go with the --policy" in err[0], err


def test_a_committed_policy_is_checked_on_every_expert_run_and_a_few_runs_frames(nav):
    """checked_recipe is the recipe of the training demonstrations, every run's scenes and
    actions, with the frame colours of FRAMES_CHECKED runs spread over them (the first among
    them) and None for the rest, which are never drawn."""
    many = dataclasses.replace(nav.cloning, demonstrations=B.FRAMES_CHECKED * 2 + 3)

    class Counting(type(nav)):
        cloning = many
        frames_drawn = 0

        def render_batch(self, scenes):
            self.frames_drawn += 1
            return super().render_batch(scenes)

    world = Counting()
    config = B.base_config(world)
    full = B.recipe(world, training_demos(world), seed=0, config=config)
    world.frames_drawn = 0
    checked = B.checked_recipe(world, seed=0, config=config)
    assert world.frames_drawn == B.FRAMES_CHECKED  # one batch per run drawn
    colours = checked.pop("frame_colours")
    assert checked == {k: v for k, v in full.items() if k != "frame_colours"}
    assert colours[0] is not None and colours[-1] is not None
    assert sum(c is not None for c in colours) == B.FRAMES_CHECKED
    assert all(c is None or c == f for c, f in zip(colours, full["frame_colours"], strict=True))
    assert B.recipe_change(full, {**checked, "frame_colours": colours}) is None
    few = dataclasses.replace(nav.cloning, demonstrations=B.FRAMES_CHECKED)

    class Few(type(nav)):
        cloning = few

    small = Few()
    config = B.base_config(small)
    assert B.checked_recipe(small, seed=0, config=config) == B.recipe(
        small, training_demos(small), seed=0, config=config
    )  # FRAMES_CHECKED demonstrations: every one drawn
