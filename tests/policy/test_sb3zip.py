"""stable-baselines3 zips that stable-baselines3 itself opens: the committed PPO agent, a zip an
earlier training script wrote (no optimizer) once repaired, a finetuned copy dfa saves beside its
checkpoint, and a zip the training script writes. Each is opened with SB3's own PPO.load and
acts as dfa's loader of the same file does."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from policy.checkpoint import save_policy
from policy.outside import load
from policy.sb3zip import OPTIMIZER, SB3_ZIP, WEIGHTS, members, with_optimizer
from policy.train import TrainConfig, behaviour_clone
from sim import get_world
from sim.core import files

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "docs" / "examples"
ZIP = EXAMPLES / "doorkey5x5_ppo.zip"
WORLD = "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12"


@pytest.fixture(scope="module")
def world():
    return get_world(WORLD)


@pytest.fixture(scope="module")
def frames(world):
    scenes = [world.train_task(s).scene for s in range(12)]
    scenes += [world.test_task("object_ti", s).scene for s in range(4)]
    return world.render_batch(scenes)  # (16, 60, 60, 3) uint8


def sb3_load(path: Path):
    from stable_baselines3 import PPO

    return PPO.load(path, device="cpu")


def assert_same_actions(model, policy, frames) -> None:
    """SB3's own model and dfa's loader of the same file: the same actions, and the same
    action distribution up to float rounding."""
    actions, _ = model.predict(frames, deterministic=True)
    np.testing.assert_array_equal(actions, policy.act(frames))
    with torch.no_grad():
        obs, _ = model.policy.obs_to_tensor(frames)
        theirs = model.policy.get_distribution(obs).distribution.logits.numpy()
    ours = torch.log_softmax(torch.from_numpy(policy.outputs(frames)), dim=1).numpy()
    np.testing.assert_allclose(theirs, ours, atol=1e-4)


def tensors(raw: bytes) -> dict[str, torch.Tensor]:
    import io

    return torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)


def test_the_committed_zip_opens_with_ppo_load_and_acts_as_dfa_reads_it(world, frames):
    assert_same_actions(sb3_load(ZIP), load(f"sb3:{ZIP}", world), frames)
    info = (EXAMPLES / "doorkey5x5_ppo.json").read_text()
    assert files.sha256(ZIP) in info  # the facts beside it name these bytes


def test_a_zip_without_optimizer_is_repaired_and_keeps_its_weights(world, frames, tmp_path):
    """A zip as the earlier training script wrote it (the optimizer stripped) is refused by
    PPO.load; with_optimizer adds a fresh optimizer and changes no other byte."""
    stripped = tmp_path / "stripped.zip"
    with zipfile.ZipFile(ZIP) as src, zipfile.ZipFile(stripped, "w", zipfile.ZIP_DEFLATED) as z:
        for name in src.namelist():
            if name != OPTIMIZER:
                z.writestr(name, src.read(name))
    with pytest.raises(KeyError, match=r"policy\.optimizer"):
        sb3_load(stripped)
    before = members(stripped)
    policy = load(f"sb3:{stripped}", world)
    assert with_optimizer(stripped, policy.net.policy)
    after = members(stripped)
    assert set(after) == {*before, OPTIMIZER}
    assert all(after[name] == raw for name, raw in before.items())  # the weights' bytes too
    assert not with_optimizer(stripped, policy.net.policy)  # once only
    optimizer = tensors(after[OPTIMIZER])
    assert optimizer["state"] == {} and optimizer["param_groups"][0]["lr"] == 5e-4
    assert_same_actions(sb3_load(stripped), policy, frames)


def test_a_finetuned_sb3_policy_is_saved_as_a_zip_ppo_load_opens(world, frames, tmp_path):
    """save_policy writes sb3.zip beside the checkpoint: the original zip with the finetuned
    state dict; SB3 and dfa (from the zip, and from the checkpoint beside the original) act
    alike, and not as the original does."""
    base = load(f"sb3:{ZIP}", world)
    demos = [world.demonstrate(world.test_task("object_ti", s)) for s in range(2)]
    tuned, _ = behaviour_clone(world, demos, config=TrainConfig(steps=30, lr=1e-3), init=base)
    folder = save_policy(tuned, tmp_path / "policy-0001")
    exported = folder / SB3_ZIP
    model = sb3_load(exported)
    assert_same_actions(model, tuned, frames)
    assert_same_actions(model, load(f"sb3:{exported}", world), frames)
    assert not np.array_equal(tuned.outputs(frames), base.outputs(frames))
    original, written = members(ZIP), members(exported)
    assert set(written) == set(original)
    assert all(written[n] == original[n] for n in original if n != WEIGHTS)
    state = tensors(written[WEIGHTS])
    assert set(state) == set(tensors(original[WEIGHTS]))  # SB3's own key names
    reloaded = load(f"sb3:{ZIP}", world, weights=folder)
    np.testing.assert_array_equal(reloaded.outputs(frames), tuned.outputs(frames))


def test_no_zip_is_made_from_a_file_that_changed_since_loading(world, tmp_path):
    copy = tmp_path / "agent.zip"
    copy.write_bytes(ZIP.read_bytes())
    policy = load(f"sb3:{copy}", world).copy()
    with zipfile.ZipFile(copy, "a") as z:
        z.writestr("note.txt", b"changed")
    folder = save_policy(policy, tmp_path / "policy-0001")
    assert (folder / "model.safetensors").is_file() and not (folder / SB3_ZIP).exists()


@pytest.mark.slow
def test_the_training_script_writes_a_zip_ppo_load_opens(world, frames, tmp_path):
    """The script trains (briefly) and writes its files in the current folder by default;
    PPO.load opens the zip, which acts as dfa reads it, and the ONNX export beside it agrees."""
    script = EXAMPLES / "train_sb3_doorkey.py"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    args = [sys.executable, str(script), "--env", "MiniGrid-DoorKey-5x5-v0"]
    args += ["--steps", "1024", "--episodes", "2"]  # one PPO update; a hang guard, not a bound
    subprocess.run(args, cwd=tmp_path, env=env, check=True, capture_output=True, timeout=1500)
    made = tmp_path / "doorkey5x5_ppo.zip"
    assert {p.name for p in tmp_path.iterdir()} >= {made.name, "doorkey5x5_ppo.onnx"}
    assert files.sha256(made) in (tmp_path / "doorkey5x5_ppo.json").read_text()
    assert tensors(members(made)[OPTIMIZER])["state"] == {}  # settings, no running averages
    policy = load(f"sb3:{made}", world)
    assert_same_actions(sb3_load(made), policy, frames)
    onnx = load(f"onnx:{tmp_path / 'doorkey5x5_ppo.onnx'}", world)
    np.testing.assert_allclose(onnx.outputs(frames), policy.outputs(frames), atol=1e-4)
