"""The sweep's expert check on the tabletop: scenes that differ only in the world's appearance
concepts (its colours), replayed with the same actions, are simulated once, and every scene
is judged as if it had been simulated itself."""

from __future__ import annotations

import numpy as np

from search.sweep import cell_keys, key_edit
from search.sweep.rollouts import replay_success
from sim import get_world


def test_scenes_that_only_look_different_are_simulated_once(monkeypatch):
    world = get_world("tabletop")
    assert world.appearance_concepts == frozenset({"colour"})
    task = world.train_task(0)
    demo = world.demonstrate(task)
    keys = cell_keys(world.space)
    colours = [k for k in keys if k[1] == "colour" and k[0] in ("object", "goal")][:6]
    shapes = [k for k in keys if k[1] == "shape" and k[0] == "object"][:3]
    recolour, *looks = [e for e in (key_edit(task.scene, k) for k in colours) if e is not None]
    moves = [e for e in (key_edit(task.scene, k) for k in shapes) if e is not None]
    reshaped = [world.apply(task.scene, e) for e in moves]
    scenes = [task.scene, *(world.apply(task.scene, e) for e in [recolour, *looks]), *reshaped]
    # each shape once more in another colour: the same motion, its own looks
    scenes += [world.apply(s, recolour) for s in reshaped]
    # and all of them again with the object put back where it was picked: R' not met
    x, y = task.scene.obj("object").pos[:2]
    stay = np.array([[x, y, x, y]], np.float32)  # (T, 4)
    actions = np.stack([demo.actions] * len(scenes) + [stay] * len(scenes))  # (B, T, 4)
    scenes += scenes
    expected = [
        world.replay(task.with_scene(s), a).success for s, a in zip(scenes, actions, strict=True)
    ]
    assert any(expected) and not all(expected)

    stepped = []
    step = world.step_batch

    def counting(batch, actions):
        stepped.append(len(batch))
        return step(batch, actions)

    monkeypatch.setattr(world, "step_batch", counting)
    got = replay_success(world, [task] * len(scenes), scenes, actions)
    assert got == expected
    # per actions: the unedited scene with its recolourings, and each shape with its own
    assert sum(stepped) == 2 * (1 + len(moves)) < len(scenes)
