"""Random shifts of the frames while cloning (TrainConfig.shift_px, World.cloning's): each
drawn frame moved by its own few pixels, its edges repeated; off (0) for every policy trained
before they were chosen."""

from __future__ import annotations

import numpy as np
import torch

from policy.base import recipe
from policy.train import TrainConfig, behaviour_clone, shifted, training_demos


def test_each_frame_is_moved_whole_by_its_own_shift_with_its_edges_repeated():
    gen = np.random.default_rng(0)
    frames = torch.from_numpy(gen.integers(0, 256, size=(64, 20, 30, 3), dtype=np.uint8))
    out = shifted(frames, 3, np.random.default_rng(1))
    assert out.dtype == torch.uint8 and out.shape == frames.shape
    dy, dx = np.random.default_rng(1).integers(0, 7, size=(2, 64)) - 3  # what it drew
    moves = set()
    for f, o, y, x in zip(frames.numpy(), out.numpy(), dy, dx, strict=True):
        # output pixel (i, j) is input pixel (i + y, j + x), clamped to the frame
        rows = np.clip(np.arange(20) + y, 0, 19)
        cols = np.clip(np.arange(30) + x, 0, 29)
        np.testing.assert_array_equal(o, f[rows][:, cols])
        moves.add((int(y), int(x)))
    assert len(moves) > 20  # not one shift for the batch: 64 draws of 49 moves


def test_the_recipe_names_shifts_only_where_there_are_any(nav):
    demos = training_demos(nav)[:2]
    assert "shift_px" not in recipe(nav, demos, seed=0, config=TrainConfig())["train"]
    shifting = recipe(nav, demos, seed=0, config=TrainConfig(shift_px=2))
    assert shifting["train"]["shift_px"] == 2


def test_cloning_with_shifts_is_seeded_and_differs_from_cloning_without(nav):
    demos = training_demos(nav)[:3]
    config = TrainConfig(steps=20, shift_px=2)
    _, first = behaviour_clone(nav, demos, config=config)
    _, again = behaviour_clone(nav, demos, config=config)
    _, plain = behaviour_clone(nav, demos, config=TrainConfig(steps=20))
    assert first == again
    assert first[0] != plain[0] or first[1] != plain[1]
