"""Saliency maps of a failed rollout drawn over its frames: a heat-coloured RGBA layer for the
recording, the same heat blended into the frames for the page.

A map is float32 (T, H, W) in [0, 1] (policy.saliency.saliency_maps, one per step that the
demonstration has an action for). 0 leaves a pixel as it is; larger values cover it with red,
then orange and yellow, more opaque (up to ALPHA_MAX), so the frame stays readable beneath.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfa_viz.run_record import RunRecord
from sim.core import World

ALPHA_MAX = 0.85


@dataclass(frozen=True, eq=False)
class SaliencyLayer:
    """The saliency of a failed rollout by one method (policy.methods.METHODS)."""

    method: str
    maps: np.ndarray  # (T, H, W) float32 in [0, 1]: one per explained step, frames 0 .. T-1


def failed_saliency(world: World, policy, record: RunRecord, method: str) -> SaliencyLayer | None:
    """The maps of the record's failed rollout against its demonstration by `method`; None
    while there is no demonstration to explain the policy's actions against. A policy that is
    not one of the project's image policies, or a bad method, is a UserError."""
    from policy.saliency import saliency_maps

    if record.demo is None:
        return None
    maps = saliency_maps(world, policy, record.rollout, record.demo, method, seed=record.seed)
    return SaliencyLayer(method, maps)


def heat_rgba(maps: np.ndarray) -> np.ndarray:
    """uint8 (..., H, W, 4) from maps (..., H, W) in [0, 1]: colour red -> yellow with the value,
    alpha ALPHA_MAX * value ** 0.75 (faint attributions fade out, stronger ones stand out)."""
    v = np.clip(np.asarray(maps, np.float32), 0.0, 1.0)
    rgba = np.stack([np.ones_like(v), v, 0.3 * v * v, ALPHA_MAX * v**0.75], axis=-1)
    return np.round(255 * rgba).astype(np.uint8)


def blend(frames: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """uint8 (..., H, W, 3): frames (..., H, W, 3) uint8 with heat_rgba(maps) composited over."""
    assert frames.dtype == np.uint8 and frames.shape[:-1] == np.shape(maps), (
        f"frames {frames.dtype} {frames.shape} and maps {np.shape(maps)} do not match"
    )
    rgba = heat_rgba(maps).astype(np.float32) / 255.0
    alpha = rgba[..., 3:]  # (..., H, W, 1)
    out = frames.astype(np.float32) * (1.0 - alpha) + 255.0 * rgba[..., :3] * alpha
    return np.round(out).astype(np.uint8)
