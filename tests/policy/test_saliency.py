"""Saliency maps by captum and their reduction to concepts: real policies and a constructed one."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from torch import nn

from policy import ImagePolicy, Policy, PolicyConfig, base_policy, failing_test_task
from policy.concept_saliency import concept_scores, prepare, saliency_ranking
from policy.methods import METHODS
from policy.saliency import SaliencyConfig, attribute, grad_cam_layer, saliency_maps
from sim import get_world
from sim.core import Trajectory, UserError
from sim.core.visible import slot_masks

QUICK = SaliencyConfig(ig_steps=16, occlusion_px=6, shap_samples=32)  # coarser, same code


def _first(traj: Trajectory, steps: int) -> Trajectory:
    """The first `steps` steps of a trajectory (tests explain a few steps, not all)."""
    return Trajectory(
        traj.scenes[: steps + 1], traj.observations[: steps + 1], traj.actions[:steps], False
    )


def _few(frames, steps: int):
    return replace(
        frames,
        obs=frames.obs[:steps],
        actions=frames.actions[:steps],
        masks=frames.masks[:, :steps],
        features=frames.features[:steps],
    )


def _looks_only_at(world, scene, slot: str) -> Policy:
    """A policy whose action is a linear function of one object's pixels only: a 1x1
    convolution summing the channels, then a linear head whose weights are zero off the
    object's mask."""
    h, w, _ = world.obs_shape
    net = ImagePolicy(PolicyConfig(world.name, world.obs_shape, world.action_dim, False))
    conv = nn.Conv2d(3, 1, 1)
    head = nn.Linear(h * w, world.action_dim)
    (mask,) = slot_masks(world, [scene])[:, [s.name for s in world.space.slots].index(slot)]
    m = mask.ravel().astype(np.float32)
    with torch.no_grad():
        conv.weight.fill_(1.0)
        conv.bias.zero_()
        head.weight.copy_(torch.from_numpy(np.stack([m, -m]) * 0.02))
        head.bias.zero_()
    net.trunk = nn.Sequential(conv, nn.Flatten())
    net.head = head
    return Policy(net)


@pytest.fixture(scope="module")
def looking(nav):
    task = nav.test_task("distractor_ti", 0)  # goal and distractor both in view
    policy = _looks_only_at(nav, task.scene, "distractor")
    rollout, demo = _first(nav.rollout(task, policy), 4), _first(nav.demonstrate(task), 4)
    return task, policy, prepare(nav, task, rollout, demo)


@pytest.mark.parametrize("method", ["integrated_gradients", "occlusion", "kernel_shap"])
def test_the_mass_lands_on_the_object_the_policy_looks_at(looking, method):
    _, policy, frames = looking
    ranking = saliency_ranking(policy, frames, method, seed=0)
    assert ranking.groups[0] == ("distractor",), ranking
    names = [c.name for c in frames.concepts]
    scores = dict(zip(ranking.concepts, ranking.scores, strict=True))
    goal = max(scores[n] for n in names if n.startswith("goal."))
    assert scores["distractor.presence"] > 3 * goal, scores  # not a near tie


def test_integrated_gradients_puts_nothing_outside_the_object(looking):
    _, policy, frames = looking
    maps = attribute(policy, frames.obs, frames.actions, "integrated_gradients")
    k = [c.name for c in frames.concepts].index("distractor.presence")
    inside = concept_scores(frames, maps)[k]
    assert inside > 0.99 * maps.sum()


def test_grad_cam_uses_the_last_convolution_with_a_map(nav_policy):
    layer = grad_cam_layer(nav_policy.net)  # 36x36 frames: the third conv's output is 1x1
    convs = [m for m in nav_policy.net.trunk if isinstance(m, nn.Conv2d)]
    assert layer is convs[1]
    tabletop = ImagePolicy(PolicyConfig("tabletop", (80, 80, 3), 4, False))
    assert grad_cam_layer(tabletop) is [m for m in tabletop.trunk if isinstance(m, nn.Conv2d)][-1]


def test_pixels_give_the_policy_s_own_outputs(nav_policy, nav):
    obs = nav.render_batch([nav.test_task("object_ti", s).scene for s in range(4)])
    with torch.no_grad():
        a = nav_policy.net(torch.from_numpy(obs)).numpy()
        b = nav_policy.net.pixels(torch.from_numpy(obs).float()).numpy()
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ["nav2d", "doorkey"])
def test_every_method_ranks_every_concept_finitely_on_the_base_policy(name):
    world = get_world(name)
    policy = base_policy(world)
    task, rollout = failing_test_task(world, policy, "distractor_ti", 0)
    demo = _first(world.demonstrate(task), 3)
    frames = prepare(world, task, _first(rollout, 3), demo)
    names = sorted(c.name for c in frames.concepts)
    for method in METHODS:
        ranking = saliency_ranking(policy, frames, method, seed=0, config=QUICK)
        assert sorted(ranking.concepts) == names, method
        assert np.isfinite(ranking.scores).all() and min(ranking.scores) >= 0, method
        assert list(ranking.scores) == sorted(ranking.scores, reverse=True), method


def test_maps_for_the_page_are_one_per_step_in_unit_range(nav, nav_policy):
    task, rollout = failing_test_task(nav, nav_policy, "object_ti", 0)
    rollout, demo = _first(rollout, 6), _first(nav.demonstrate(task), 5)
    for method in METHODS:
        maps = saliency_maps(nav, nav_policy, rollout, demo, method, config=QUICK)
        assert maps.shape == (5, 36, 36), method  # the steps the demonstration has actions for
        assert maps.dtype == np.float32 and maps.min() >= 0 and maps.max() == 1.0, method
    shap = [saliency_maps(nav, nav_policy, rollout, demo, "kernel_shap", seed=3) for _ in "ab"]
    np.testing.assert_array_equal(*shap)  # seeded


def test_bad_methods_and_non_finite_attributions_are_refused(nav, nav_policy):
    task, rollout = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    with pytest.raises(UserError, match="unknown saliency method 'lrp'"):
        saliency_maps(nav, nav_policy, rollout, demo, "lrp")
    broken = nav_policy.copy()
    with torch.no_grad():
        broken.net.head[-1].weight.fill_(float("nan"))
    with pytest.raises(UserError, match="non-finite"):
        attribute(broken, rollout.observations[:2], demo.actions[:2], "integrated_gradients")
