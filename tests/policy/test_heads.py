"""The policy's heads: the spatial-softmax (keypoint) head's shapes, checkpoint and Grad-CAM
layer; the default head leaves the committed policies of record as they were."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from policy import base as B
from policy import load_policy, save_policy
from policy.model import ImagePolicy, Policy, PolicyConfig, SpatialSoftmax
from policy.saliency import grad_cam_layer
from policy.train import base_arch
from sim import PAPER_WORLDS, get_world
from sim.core import UserError


def test_spatial_softmax_gives_each_maps_peak_as_x_y():
    maps = torch.full((2, 3, 5, 7), -50.0)
    maps[0, 0, 0, 0] = maps[0, 1, 4, 6] = maps[1, 2, 2, 3] = 50.0  # one hot cell each
    maps[0, 2] = maps[1, 0] = maps[1, 1] = 0.0  # flat: the frame's centre
    out = SpatialSoftmax(5, 7)(maps)
    assert out.shape == (2, 6)  # (x, y) of each of the 3 maps
    want = [[-1, -1, 1, 1, 0, 0], [0, 0, 0, 0, 0, 0]]
    assert np.allclose(out.detach().numpy(), want, atol=1e-3)


def test_a_spatial_softmax_policy_acts_saves_and_loads(nav, tmp_path):
    config = PolicyConfig("nav2d", (36, 36, 3), 2, False, head="spatial_softmax")
    assert config.strides == (2, 2, 1)  # the finer trunk: 13 x 13 maps, not the paper's 1 x 1
    policy = Policy(ImagePolicy(config))
    obs = np.random.default_rng(0).integers(0, 256, (5, 36, 36, 3), dtype=np.uint8)
    assert policy.act(obs).shape == (5, 2)
    folder = save_policy(policy, tmp_path / "ckpt")
    assert json.loads((folder / "config.json").read_text())["policy"]["head"] == "spatial_softmax"
    again = load_policy(folder, world=nav)
    assert again.config == config
    assert np.array_equal(again.act(obs), policy.act(obs))
    assert grad_cam_layer(again.net) is again.net.trunk[-3]  # the last convolution

    doc = json.loads((folder / "config.json").read_text())
    doc["policy"]["head"] = "attention"
    (folder / "config.json").write_text(json.dumps(doc))
    with pytest.raises(UserError, match="head must be one of flatten, spatial_softmax"):
        load_policy(folder, world=nav)


@pytest.mark.parametrize("name", PAPER_WORLDS)
def test_the_default_head_loads_the_committed_policies_bit_for_bit(name):
    world = get_world(name)
    folder = B.record_folder(world)
    stored = json.loads((folder / "config.json").read_text())["policy"]
    assert "head" not in stored
    assert json.loads(json.dumps(base_arch(world).to_dict())) == stored
    policy = load_policy(folder, world=world)
    assert policy.config.head == "flatten"
    state, tensors = policy.net.state_dict(), load_file(folder / "model.safetensors")
    assert set(state) == set(tensors)
    assert all(torch.equal(state[k], tensors[k]) for k in tensors)
