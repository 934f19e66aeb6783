"""The field's checks of a saliency map where the ground truth is known: how much of its mass
lies on the cause's pixels, how much on no object, whether deleting what it points at moves
the action, and whether it depends on the weights at all.

  relevance_mass   Quantus' RelevanceMassAccuracy (Arras et al., 2022): the map's mass inside
                   the ground-truth mask over its whole mass (maps >= 0). Here the mask is the
                   planted cause's pixels (its object's; every lava tile for lava.presence),
                   and beside it the mass on pixels of no object (background, walls, the agent).
  deletion_curve   the action distance after the most-attributed pixels of each frame are set
                   black (the methods' baseline), a fraction of the frame at a time (FRACTIONS):
                   ||pi(s) - a|| for continuous actions, 1 - p(a | s) for discrete ones, a the
                   demonstrated action; `deletion_score` is the curve's mean over the fractions
                   over the distance on the whole frames (below 1: deleting what the map
                   points at brings the action closer to the demonstration).
  randomised       the model-parameter randomisation test (Adebayo et al., 2018), cascading:
                   the policy's convolutions and linear layers are re-initialised from the top
                   one down (seeded; GroupNorm's affine parameters stay), the maps recomputed,
                   and each compared with the trained policy's by Spearman's rank correlation
                   over the pixels of the frames that either map gives a non-zero value (a
                   pixel both leave at exactly 0 ties whatever the weights: with a black
                   baseline, every black pixel for Integrated Gradients, 95% of a nav2d frame);
                   a map that survives randomisation (a correlation near 1) does not explain
                   the policy.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from policy.model import Policy
from policy.saliency import SaliencyConfig, attributions

FRACTIONS = (1 / 64, 1 / 32, 1 / 16, 1 / 8, 1 / 4)
"""Shares of a frame's pixels deleted, in the deletion curve's order."""


def relevance_mass(maps: np.ndarray, mask: np.ndarray) -> float:
    """The share of a non-negative map's mass inside a mask (both (T, H, W)); nan without mass."""
    assert maps.shape == mask.shape, (maps.shape, mask.shape)
    total = float(np.clip(maps, 0, None).sum(dtype=np.float64))
    if total <= 0:
        return float("nan")
    return float(np.clip(maps[mask], 0, None).sum(dtype=np.float64)) / total


def action_distance(policy: Policy, obs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """float64 (T,): how far the policy's action on each frame is from the demonstrated one."""
    with torch.no_grad():
        out = policy.net.pixels(torch.from_numpy(np.asarray(obs, np.float32)))  # (T, A | n)
    if policy.discrete:
        p = torch.softmax(out.double(), dim=1)
        a = torch.as_tensor(np.asarray(actions, np.int64)).reshape(-1, 1)
        return (1.0 - p.gather(1, a)[:, 0]).numpy()
    a = torch.as_tensor(np.asarray(actions, np.float32).reshape(len(obs), -1))
    return torch.linalg.vector_norm((out - a).double(), dim=1).numpy()


def deletion_curve(
    policy: Policy,
    obs: np.ndarray,
    actions: np.ndarray,
    scores: np.ndarray,
    fractions: tuple[float, ...] = FRACTIONS,
) -> np.ndarray:
    """float64 (1 + F,): the mean action distance over the frames with nothing deleted, then
    with each fraction of each frame's pixels deleted, highest `scores` (T, H, W) first (ties
    in pixel order)."""
    t, h, w, _ = obs.shape
    order = np.argsort(-scores.reshape(t, -1), axis=1, kind="stable")  # (T, H*W)
    curve = [float(action_distance(policy, obs, actions).mean())]
    for f in fractions:
        gone = np.zeros((t, h * w), bool)
        np.put_along_axis(gone, order[:, : round(f * h * w)], True, axis=1)
        deleted = np.where(gone.reshape(t, h, w, 1), 0, obs).astype(np.uint8)
        curve.append(float(action_distance(policy, deleted, actions).mean()))
    return np.array(curve)


def deletion_score(curve: np.ndarray) -> float:
    """The curve's mean over the deleted fractions relative to nothing deleted (nan at 0)."""
    return float(np.mean(curve[1:]) / curve[0]) if curve[0] > 0 else float("nan")


def layers_from_the_top(policy: Policy) -> list[nn.Module]:
    """The network's convolutions and linear layers, the last one (the action head) first."""
    net = policy.net
    return [m for m in net.modules() if isinstance(m, (nn.Conv2d, nn.Linear))][::-1]


def randomised(
    policy: Policy,
    obs: np.ndarray,
    actions: np.ndarray,
    method: str,
    *,
    features: np.ndarray | None = None,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> dict[str, list[float]]:
    """Per reading ("abs": the magnitude; "signed": the signed attribution), Spearman's
    correlation between the trained policy's map and the map with the top 1, 2, ... layers
    re-initialised (layers_from_the_top), one per layer count; nan where a map is constant."""
    from scipy.stats import spearmanr

    def maps(p: Policy) -> dict[str, np.ndarray]:
        unsigned, signed = attributions(
            p, obs, actions, method, features=features, seed=seed, config=config
        )
        return {"abs": unsigned.ravel(), "signed": signed.ravel()}

    def rho(a: np.ndarray, b: np.ndarray) -> float:
        some = (a != 0) | (b != 0)  # pixels both leave at 0 would tie under any weights
        a, b = a[some], b[some]
        if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
            return float("nan")
        return float(spearmanr(a, b).statistic)

    trained = maps(policy)
    out: dict[str, list[float]] = {k: [] for k in trained}
    copy = policy.copy()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        for layer in layers_from_the_top(copy):
            layer.reset_parameters()
            again = maps(copy)
            for k in out:
                out[k].append(rho(trained[k], again[k]))
    return out
