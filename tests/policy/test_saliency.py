"""Saliency maps by captum and their reduction to concepts: real policies and a constructed one."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from torch import nn

from policy import ImagePolicy, Policy, PolicyConfig, base_policy, failing_test_task
from policy.concept_saliency import (
    DIVERGED,
    before_divergence,
    concept_scores,
    prepare,
    saliency_ranking,
    saliency_readouts,
)
from policy.methods import METHODS
from policy.saliency import (
    SaliencyConfig,
    attribute,
    explained_steps,
    grad_cam_layer,
    live_steps,
    occlusion_window,
    saliency_maps,
)
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


class _Gate(nn.Module):
    """Multiplies the normalised frame by a fixed 0/1 mask: every pixel off it is cut off."""

    def __init__(self, mask: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("mask", torch.from_numpy(mask.astype(np.float32)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.mask  # (B, 3, H, W) * (H, W)


def looks_only_at(world, scene, slot: str, *, seed: int = 0) -> Policy:
    """A policy of the world's own kind (continuous or logits) whose output is a function of one
    object's pixels only: the frame gated by the object's mask in `scene`, a 1x1 convolution
    without bias (two channels: brightness and a red-green contrast), a seeded linear head."""
    h, w, _ = world.obs_shape
    net = ImagePolicy(PolicyConfig(world.name, world.obs_shape, world.action_dim, world.discrete))
    (mask,) = slot_masks(world, [scene])[:, [s.name for s in world.space.slots].index(slot)]
    assert mask.any(), f"{slot} has no pixels in this scene"
    conv = nn.Conv2d(3, 2, 1, bias=False)
    head = nn.Linear(2 * h * w, world.action_dim)
    draw = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        conv.weight.copy_(torch.tensor([[1.0, 1.0, 1.0], [1.0, -1.0, 0.0]]).reshape(2, 3, 1, 1))
        head.weight.copy_(torch.randn(world.action_dim, 2 * h * w, generator=draw) * 0.05)
        head.bias.zero_()
    net.trunk = nn.Sequential(_Gate(mask), conv, nn.Flatten())
    net.head = head
    return Policy(net)


def _grown(mask: np.ndarray, px: int) -> np.ndarray:
    """The (T, H, W) mask grown by `px` pixels in every direction (a square neighbourhood)."""
    out = mask.copy()
    h, w = mask.shape[1:]
    for dy in range(-px, px + 1):
        for dx in range(-px, px + 1):
            shifted = np.zeros_like(mask)
            shifted[:, max(dy, 0) : h + min(dy, 0), max(dx, 0) : w + min(dx, 0)] = mask[
                :, max(-dy, 0) : h + min(-dy, 0), max(-dx, 0) : w + min(-dx, 0)
            ]
            out |= shifted
    return out


# (world, shift, the object the toy policy looks at): a continuous world with two objects in
# view, a discrete one where the cause is a 2x2-pixel key among four objects, 80x80 frames
KNOWN_CAUSES = [
    ("nav2d", "distractor_ti", "distractor"),
    ("nav2d", "distractor_ti", "goal"),
    ("doorkey", "distractor_ti", "key"),
    ("tabletop", "distractor_ti", "distractor0"),
]


@pytest.fixture(scope="module", params=KNOWN_CAUSES, ids=lambda p: f"{p[0]}-{p[2]}")
def known_cause(request):
    name, shift, slot = request.param
    world = get_world(name)
    task = world.test_task(shift, 0)
    demo = _first(world.demonstrate(task), 4)  # real frames of the world, four steps
    policy = looks_only_at(world, task.scene, slot)
    frames = prepare(world, task, demo, demo)
    k = next(i for i, g in enumerate(frames.groups) if g == (slot,))
    return world, slot, policy, frames, k


@pytest.mark.parametrize("method", METHODS)
def test_every_method_puts_the_mass_on_the_only_object_the_policy_sees(known_cause, method):
    world, slot, policy, frames, k = known_cause
    maps = attribute(policy, frames.obs, frames.actions, method, features=frames.features)
    assert maps.sum() > 0, method
    # a method's resolution: Occlusion spreads a patch's change over the patch, so the object
    # is grown by the patch's reach; the others resolve pixels here (a 1x1 convolution)
    reach = occlusion_window(world.obs_shape[0])[0] - 1 if method == "occlusion" else 0
    region = _grown(frames.masks[k], reach)
    assert maps[region].sum() >= 0.99 * maps.sum(), (method, maps[region].sum() / maps.sum())
    ranking = saliency_ranking(policy, frames, method, seed=0)
    assert ranking.groups[0] == (slot,), (method, ranking)
    scores = concept_scores(frames, maps)
    others = [scores[j] for j, g in enumerate(frames.groups) if slot not in g]
    assert not others or scores[k] > 3 * max(others), (method, scores)  # not a near tie


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


@pytest.mark.parametrize("method", ["integrated_gradients", "occlusion", "kernel_shap"])
def test_the_signed_reading_blames_the_object_only_when_it_pushes_the_action_away(
    known_cause, method
):
    """Explained against the policy's own action on a black frame, the object's pixels push the
    action away from the demonstration; against its action on the frame, they pull it there.
    The magnitude names the object either way; the signed reading blames it first only in the
    first case (Grad-CAM's sign is its gradient-weighted activations', not a share of the
    output, so it is not held to this)."""
    world, slot, policy, frames, _ = known_cause
    with torch.no_grad():
        on_frame = policy.net.pixels(torch.from_numpy(frames.obs).float())
        on_black = policy.net.pixels(torch.zeros(frames.obs.shape))
    if world.discrete:  # the logit the object lowers most, or raises most
        push, pull = (on_frame - on_black).argmin(dim=1), (on_frame - on_black).argmax(dim=1)
    else:
        push, pull = on_black, on_frame
    for actions, pushes in ((push, True), (pull, False)):
        explained = replace(frames, actions=actions.numpy())
        readings = saliency_readouts(policy, explained, method, seed=0)
        assert readings[("abs", "all")].groups[0] == (slot,), (method, pushes)
        signed = readings[("signed", "all")]
        if pushes:
            assert signed.groups[0] == (slot,) and signed.scores[0] > 0, (method, signed)
        else:
            assert signed.groups[-1] == (slot,) and signed.scores[-1] < 0, (method, signed)


def test_the_steps_before_divergence_are_those_whose_frames_are_the_demonstration_s(nav):
    doorkey = get_world("doorkey")
    for world in (doorkey, nav):
        task, rollout = failing_test_task(world, base_policy(world), "object_ti", 0)
        demo = world.demonstrate(task)
        steps = explained_steps(world, rollout, demo)
        assert before_divergence(world, demo, demo) == explained_steps(world, demo, demo)
        n = before_divergence(world, rollout, demo)
        assert 1 <= n < steps, (world.name, n)  # the failed rollout leaves the demonstration
        frames = np.any(rollout.observations[: n + 1] != demo.observations[: n + 1], axis=-1)
        share = frames.reshape(n + 1, -1).mean(axis=1)  # (n + 1,) pixels that differ
        if world.discrete:
            assert not share[:n].any() and share[n] > 0, share
        else:
            assert (share[:n] <= DIVERGED).all() and share[n] > DIVERGED, share


def test_explained_steps_end_where_an_episode_ends():
    """A DoorKey demonstration reaches the goal before the horizon; its later steps only repeat
    the last frame and action, so they are not explained."""
    world = get_world("doorkey")
    policy = base_policy(world)
    task, rollout = failing_test_task(world, policy, "object_ti", 0)
    demo = world.demonstrate(task)
    ended = live_steps(world, demo)
    assert ended < demo.horizon, ended
    assert world.done(demo.scenes[ended]) and not any(map(world.done, demo.scenes[:ended]))
    steps = explained_steps(world, rollout, demo)
    assert steps == min(ended, live_steps(world, rollout)), steps
    maps = saliency_maps(world, policy, rollout, demo, "grad_cam")
    assert len(maps) == steps, (len(maps), steps)
