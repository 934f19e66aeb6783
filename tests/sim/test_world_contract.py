"""One contract for every world: the registered ones, MiniGrid environments made into worlds,
and the small example world of docs/bring-your-own.md. A world is tested the day it exists."""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sim
from sim.core import SHIFTS, Edit, Key, apply, single_changes
from sim.core.view3d import View3D

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
MINIGRID = [
    "minigrid:MiniGrid-DoorKey-5x5-v0",
    "minigrid:MiniGrid-DoorKey-8x8-v0",
    "minigrid:MiniGrid-Unlock-v0",
    "minigrid:MiniGrid-LavaGapS5-v0",
    "minigrid:MiniGrid-Fetch-5x5-N2-v0",
    "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12",
]


def _register_example() -> None:
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    sim.register_world("corridor", "corridor:CorridorWorld")


_register_example()
WORLDS = [n for n in sim.world_names() if not n.endswith(":...")] + MINIGRID


@pytest.fixture(scope="module", params=WORLDS)
def world(request):
    return sim.get_world(request.param)


def _scenes(world, n: int = 4) -> list:
    scenes = [world.sample_scene(seed) for seed in range(n)]
    if world.benchmark:
        scenes += [world.test_task(shift, 0).scene for shift in world.shifts]
    return scenes


def test_the_gymnasium_environment_passes_check_env(world):
    env = world.make_env()
    check_env(env.unwrapped if isinstance(env, gymnasium.Wrapper) else env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == world.obs_shape and obs.dtype == np.uint8
    assert np.array_equal(obs, world.render(world.sample_scene(0)))


def test_rendering_is_deterministic_batched_and_of_the_declared_shape(world):
    scenes = _scenes(world)
    frames = world.render_batch(scenes)
    assert frames.shape == (len(scenes), *world.obs_shape) and frames.dtype == np.uint8
    assert np.array_equal(frames, world.render_batch(scenes))
    for s, f in zip(scenes, frames, strict=True):
        assert np.array_equal(world.render(s), f)


def test_stepping_is_deterministic_and_batch_equals_single(world):
    rng = np.random.default_rng(0)
    scenes = _scenes(world)
    for _ in range(min(world.horizon, 6)):
        if world.discrete:
            actions = rng.integers(world.action_dim, size=len(scenes))
        else:
            actions = rng.uniform(-0.3, 0.3, size=(len(scenes), world.action_dim)).astype(
                np.float32
            )
        batch = world.step_batch(scenes, actions)
        assert batch == world.step_batch(scenes, actions)
        single = [world.step_batch([s], actions[i : i + 1])[0] for i, s in enumerate(scenes)]
        assert batch == single
        scenes = batch


def test_encode_decode_and_apply_round_trip(world):
    space = world.space
    for scene in _scenes(world):
        assert space.decode(space.encode(scene), scene) == scene
        presence, values = single_changes(space, scene)
        for change in (presence + values)[:40]:
            edited = apply(space, scene, Edit.of(change))
            back = apply(
                space,
                edited,
                Edit.of(type(change)(change.slot, change.concept, change.new, change.old)),
            )
            assert back == scene
            assert space.decode(space.encode(edited), edited) == edited


def test_capabilities_are_declared(world):
    assert world.demo_input in ("waypoints", "keys", "pick_place", "file")
    if world.demo_input == "keys":
        assert world.discrete and world.keys and all(isinstance(k, Key) for k in world.keys)
        assert all(0 <= k.action < world.action_dim for k in world.keys)
        assert 0 <= world.idle_action < world.action_dim
    if world.demo_input in ("waypoints", "pick_place"):
        assert world.image_extent is not None and not world.discrete
    assert isinstance(world.lossless_frames, bool) and isinstance(world.search_first_only, bool)
    assert world.view3d is None or isinstance(world.view3d, View3D)
    assert world.action_names == () or (
        not world.discrete and len(world.action_names) == world.action_dim
    )
    assert set(world.shifts) <= set(SHIFTS)
    assert world.benchmark == bool(world.shifts)
    assert len(world.space.slots) == len({s.name for s in world.space.slots})


def test_no_non_finite_state_is_a_success(world):
    scene = world.sample_scene(0)
    task = world.task_for(scene)
    bad = type(scene)(scene.world, scene.objects, (float("nan"), *scene.agent[1:]))
    assert not world.success(task, [scene, bad])


def test_benchmark_worlds_make_their_shifts(world):
    if not world.benchmark:  # a plain world is diagnosed from a user's demonstration
        assert not world.shifts
        return
    for shift in world.shifts:
        task = world.test_task(shift, 1)
        assert task.shift == shift and task.world == world.name
        demo = world.demonstrate(task)
        assert demo.success, (shift, task.reward.instruction)
        fresh = world.fresh_tasks(task, 3, seed=1, layouts="train", shifted=True)
        assert len(fresh) == 3 and all(t.reward == task.reward for t in fresh)
