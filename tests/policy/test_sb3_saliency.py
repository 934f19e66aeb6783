"""The saliency methods take the outside stable-baselines3 agent's network apart: its logits from
float frames are the ones it acts on, gradients flow through SB3's own pixel scaling (Integrated
Gradients' attributions add up to the logit's change from a black frame), Grad-CAM hooks a
convolution of its actor's features extractor, and every method maps a MiniGrid frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from policy.methods import METHODS
from policy.model import Policy
from policy.outside import load
from policy.saliency import attributions, check_explainable, feature_labels, grad_cam_layer
from sim import get_world
from sim.core import UserError
from sim.core.visible import slot_masks

ZIP = Path(__file__).resolve().parents[2] / "docs" / "examples" / "doorkey5x5_ppo.zip"
WORLD = "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12"


@pytest.fixture(scope="module")
def world():
    return get_world(WORLD)


@pytest.fixture(scope="module")
def agent(world):
    return load(f"sb3:{ZIP}", world)


@pytest.fixture(scope="module")
def scenes(world):
    return [world.train_task(s).scene for s in range(3)]


def test_the_agents_network_is_explainable_with_its_own_logits(agent, world, scenes):
    check_explainable(agent)
    obs = world.render_batch(scenes)  # (3, 60, 60, 3) uint8
    with torch.no_grad():
        acted = agent.net(torch.from_numpy(obs))
        explained = agent.net.pixels(torch.from_numpy(obs.astype(np.float32)))
    assert torch.allclose(acted, explained, atol=1e-4)
    layer = grad_cam_layer(agent.net)
    extractor = agent.net.policy.pi_features_extractor
    assert any(layer is m for m in extractor.modules()) and isinstance(layer, nn.Conv2d)
    with pytest.raises(UserError, match="network is Linear"):
        check_explainable(
            Policy(nn.Linear(3, 7), discrete=True, obs_shape=(60, 60, 3), action_dim=7)
        )


def test_integrated_gradients_add_up_to_the_logits_change(agent, world, scenes):
    obs = world.render_batch(scenes)
    with torch.no_grad():
        logits = agent.net.pixels(torch.from_numpy(obs.astype(np.float32)))
        black = agent.net.pixels(torch.zeros(1, *obs.shape[1:]))
    target = logits.argmin(dim=1)  # the least likely action: far from the black frame's
    want = (logits.gather(1, target[:, None]) - black[0, target][:, None]).reshape(-1).numpy()
    _, signed = attributions(agent, obs, target.numpy(), "integrated_gradients")
    got = signed.reshape(len(obs), -1).sum(axis=1)
    assert np.all(np.abs(want) > 0.5), want  # something to add up to
    assert np.allclose(got, want, rtol=0.1, atol=0.1), (got, want)


def test_every_method_maps_a_minigrid_frame(agent, world, scenes):
    obs = world.render_batch(scenes[:1])
    features = feature_labels(slot_masks(world, scenes[:1]))
    assert len(np.unique(features)) >= 3  # key, door, goal and the rest of the frame
    for method in METHODS:
        unsigned, signed = attributions(
            agent, obs, np.zeros(1, np.int64), method, features=features
        )
        assert unsigned.shape == signed.shape == obs.shape[:3]
        assert np.isfinite(signed).all() and unsigned.max() > 0, method
