"""The policy contract, for every registered loader: a small real policy of each kind is made here
(an ONNX graph exported with torch.onnx, a torch module file with safetensors weights, a
stable-baselines3 PPO saved by stable-baselines3 itself), loaded through its prefix, and must
give one finite score per action for each frame, the same for a frame alone as in a batch, and,
where the kind can be trained, finetune and come back from its checkpoint with the same outputs.
A loader registered without a policy made here fails its case: each loader meets the contract."""

from __future__ import annotations

import io
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from policy.checkpoint import save_policy
from policy.loaders import loader_prefixes
from policy.outside import load
from policy.train import TrainConfig, finetune, training_demos
from sim import get_world
from sim.core import UserError

WORLD = "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12"  # 60x60 frames, 7 discrete actions
CONVERSION = "#chw,scale=1/255"  # what the module below takes: float frames channels first

NETS = '''
import torch
from torch import nn


class SmallNet(nn.Module):
    """Float frames (B, 3, 60, 60) in [0, 1] -> 7 action scores."""

    def __init__(self) -> None:
        super().__init__()
        self.conv = nn.Conv2d(3, 4, 6, 6)  # -> (B, 4, 10, 10)
        self.head = nn.Linear(4 * 10 * 10, 7)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(torch.relu(self.conv(x)).flatten(1))


def make() -> nn.Module:
    return SmallNet()
'''


def make_torch(folder: Path) -> str:
    import contract_nets
    from safetensors.torch import save_file

    torch.manual_seed(0)
    weights = folder / "small.safetensors"
    save_file(contract_nets.make().state_dict(), str(weights))
    return f"torch:contract_nets:make@{weights}{CONVERSION}"


def make_onnx(folder: Path) -> str:
    import contract_nets

    torch.manual_seed(1)
    net = contract_nets.make().eval()
    buf = io.BytesIO()
    torch.onnx.export(
        net,
        (torch.rand(2, 3, 60, 60),),
        buf,
        input_names=["frame"],
        output_names=["scores"],
        dynamic_axes={"frame": {0: "batch"}, "scores": {0: "batch"}},
        dynamo=False,
    )
    path = folder / "small.onnx"
    path.write_bytes(buf.getvalue())
    return f"onnx:{path}{CONVERSION}"


def make_sb3(folder: Path) -> str:
    import gymnasium as gym
    import minigrid  # noqa: F401  (registers the MiniGrid environments)
    from minigrid.wrappers import ImgObsWrapper, RGBImgObsWrapper
    from stable_baselines3 import PPO

    env = ImgObsWrapper(RGBImgObsWrapper(gym.make("MiniGrid-DoorKey-5x5-v0"), tile_size=12))
    model = PPO("CnnPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu", verbose=0)
    path = folder / "small_ppo.zip"
    model.save(path)
    return f"sb3:{path}"


MAKERS: dict[str, Callable[[Path], str]] = {
    "onnx": make_onnx,
    "torch": make_torch,
    "sb3": make_sb3,
}
TRAINABLE = {"onnx": False, "torch": True, "sb3": True}


@pytest.fixture(scope="module")
def world():
    return get_world(WORLD)


@pytest.fixture(scope="module")
def frames(world):
    scenes = [world.train_task(s).scene for s in range(5)]
    return world.render_batch([*scenes, world.test_task("object_ti", 0).scene])  # (6, 60, 60, 3)


@pytest.fixture(scope="module")
def spec_of(tmp_path_factory):
    """prefix -> the spec of a small policy of that kind, made once."""
    folder = tmp_path_factory.mktemp("policies")
    (folder / "contract_nets.py").write_text(NETS)
    made: dict[str, str] = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(folder))

        def spec(prefix: str) -> str:
            if prefix not in made:
                made[prefix] = MAKERS[prefix](folder)
            return made[prefix]

        yield spec
    sys.modules.pop("contract_nets", None)


def test_every_built_in_loader_has_a_case():
    assert set(MAKERS) <= set(loader_prefixes())
    assert loader_prefixes()[:3] == ("onnx", "torch", "sb3")


@pytest.mark.parametrize("prefix", loader_prefixes())
def test_outputs_are_one_finite_score_per_action(prefix, spec_of, world, frames):
    policy = load(spec_of(prefix), world)
    out = policy.outputs(frames)
    assert out.shape == (len(frames), world.action_dim) and out.dtype == np.float32
    assert np.isfinite(out).all() and out.std() > 0  # a real network, not a constant
    actions = policy.act(frames)
    assert actions.shape == (len(frames),) and actions.dtype == np.int64
    assert ((actions >= 0) & (actions < world.action_dim)).all()
    np.testing.assert_array_equal(actions, out.argmax(axis=1))
    policy.fits(world)
    assert policy.source.startswith(f"{prefix}:") and policy.origin.kind == prefix


@pytest.mark.parametrize("prefix", loader_prefixes())
def test_a_batch_gives_what_each_frame_gives_alone(prefix, spec_of, world, frames):
    policy = load(spec_of(prefix), world)
    batch = policy.outputs(frames)
    alone = np.concatenate([policy.outputs(frames[i : i + 1]) for i in range(len(frames))])
    np.testing.assert_allclose(batch, alone, rtol=1e-5, atol=1e-5)
    policy.chunk = 4  # run in chunks of at most 4 frames: 2 chunks of 3
    np.testing.assert_allclose(policy.outputs(frames), batch, rtol=1e-5, atol=1e-5)
    again = load(spec_of(prefix), world)  # the same spec loads the same policy
    np.testing.assert_array_equal(again.outputs(frames), batch)


@pytest.fixture(scope="module")
def demos(world):
    return training_demos(world)[:2]


@pytest.mark.parametrize("prefix", loader_prefixes())
def test_finetuning_where_the_kind_supports_it(prefix, spec_of, world, frames, demos, tmp_path):
    spec = spec_of(prefix)
    policy = load(spec, world)
    before = policy.outputs(frames)
    config = TrainConfig(steps=4, batch_size=8, lr=1e-2)
    if not TRAINABLE[prefix]:
        assert policy.net is None
        with pytest.raises(UserError, match="can be run but not trained"):
            finetune(world, policy, demos, config=config)
        with pytest.raises(UserError, match="no weights of its own to save"):
            save_policy(policy, tmp_path / "tuned")
        return
    tuned, losses = finetune(world, policy, demos, config=config)
    assert len(losses) == 4 and np.isfinite(losses).all()
    after = tuned.outputs(frames)
    assert after.shape == before.shape and np.isfinite(after).all()
    assert not np.allclose(after, before)  # the weights moved
    np.testing.assert_array_equal(policy.outputs(frames), before)  # the loaded one did not
    folder = save_policy(tuned, tmp_path / "tuned")
    back = load(spec, world, weights=folder)
    np.testing.assert_array_equal(back.outputs(frames), after)
    assert back.source == policy.source and back.origin == policy.origin
