"""The checks of a saliency map against a known cause: relevance mass, deletion, randomisation."""

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from policy import base_policy, failing_test_task
from policy.concept_saliency import frame_maps, prepare, reading_map
from policy.saliency_metrics import (
    action_distance,
    deletion_curve,
    deletion_score,
    layers_from_the_top,
    randomised,
    relevance_mass,
)
from tests.policy.test_saliency import _first, looks_only_at


def test_relevance_mass_is_the_share_of_the_mass_inside_the_mask():
    maps = np.zeros((2, 4, 4), np.float32)
    mask = np.zeros((2, 4, 4), bool)
    maps[0, 0, 0], maps[1, 3, 3], maps[1, 2, 2] = 3.0, 1.0, 2.0
    mask[0, 0, 0] = mask[1, 2, 2] = True
    assert relevance_mass(maps, mask) == pytest.approx(5 / 6)
    assert relevance_mass(maps, ~mask) == pytest.approx(1 / 6)
    assert math.isnan(relevance_mass(np.zeros_like(maps), mask))


@pytest.fixture(scope="module")
def pushed(nav):
    """The known-cause policy on nav2d, explained against its own action on a black frame: the
    distractor's pixels are all that push the action away from the demonstration."""
    task = nav.test_task("distractor_ti", 0)
    policy = looks_only_at(nav, task.scene, "distractor")
    demo = _first(nav.demonstrate(task), 4)
    frames = prepare(nav, task, demo, demo)
    with torch.no_grad():
        black = policy.net.pixels(torch.zeros(frames.obs.shape)).numpy()
    return policy, replace(frames, actions=black)


def test_deleting_the_blamed_pixels_brings_the_action_back_and_random_ones_do_not(pushed):
    policy, frames = pushed
    unsigned, signed = frame_maps(policy, frames, "integrated_gradients")
    blame = reading_map(unsigned, signed, "signed")
    curve = deletion_curve(policy, frames.obs, frames.actions, blame)
    assert curve[0] == pytest.approx(action_distance(policy, frames.obs, frames.actions).mean())
    assert curve[0] > 0 and max(curve[1:]) < 0.5 * curve[0], curve  # the blamed pixels gone
    noise = np.random.default_rng(0).random(blame.shape)
    at_random = deletion_score(deletion_curve(policy, frames.obs, frames.actions, noise))
    assert deletion_score(curve) < 0.5 < at_random, (deletion_score(curve), at_random)


def test_randomising_the_layers_from_the_top_changes_the_maps_not_the_policy(nav):
    policy = base_policy(nav)
    task, rollout = failing_test_task(nav, policy, "distractor_ti", 0)
    frames = prepare(nav, task, _first(rollout, 4), _first(nav.demonstrate(task), 4))
    before = [p.detach().clone() for p in policy.net.parameters()]
    rho = randomised(policy, frames.obs, frames.actions, "integrated_gradients", seed=0)
    layers = layers_from_the_top(policy)
    assert len(layers) == 5 and isinstance(layers[0], torch.nn.Linear)  # the head first
    assert all(len(v) == len(layers) for v in rho.values())
    assert all(torch.equal(a, b) for a, b in zip(before, policy.net.parameters(), strict=True))
    assert all(-1 <= r <= 1 for v in rho.values() for r in v)
    assert rho["signed"][-1] < 0.5, rho  # nothing of the trained policy's signed map is left
    same = randomised(policy, frames.obs, frames.actions, "integrated_gradients", seed=0)
    assert same == rho  # seeded
