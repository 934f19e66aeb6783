"""Stock MiniGrid environments made into worlds: the frames are the RGB wrappers' own, the
dynamics the environment's own step, the concept space read from its grids, the shifts made
from that space, and the breadth-first expert solves every task it is given."""

from __future__ import annotations

import itertools
import subprocess
import sys

import gymnasium
import numpy as np
import pytest

import sim
from sim.core import ABSENT, PRESENCE, PRESENT, Change, Edit, UserError
from sim.minigrid.world import MiniGridWorld

ENVS = [
    "MiniGrid-DoorKey-5x5-v0",
    "MiniGrid-DoorKey-8x8-v0",
    "MiniGrid-Unlock-v0",
    "MiniGrid-LavaGapS5-v0",
    "MiniGrid-Fetch-5x5-N2-v0",
]
NAMES = [f"minigrid:{e}" for e in ENVS] + [
    "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12",
    "minigrid:MiniGrid-DoorKey-5x5-v0:view=partial",
]


@pytest.fixture(scope="module", params=NAMES)
def world(request):
    return sim.get_world(request.param)


def test_frames_are_what_the_rgb_wrappers_show_a_policy(world):
    """RGBImgObsWrapper (or RGBImgPartialObsWrapper) on the environment reset with seed s shows
    exactly the world's frame of training layout s."""
    env = world.make_env()
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        assert obs.shape == world.obs_shape and obs.dtype == np.uint8
        np.testing.assert_array_equal(world.render(world.train_task(seed).scene), obs)


def test_batched_frames_are_minigrids_own_frames(world):
    """Every edit up to size 2 of a task of each shift, and the states of the expert's rollout
    from each edited scene, batched (sim.minigrid.frames) and by env.get_frame one at a time."""
    from search import combinations

    scenes = []
    for shift in world.shifts:
        task = world.test_task(shift, 0)
        edits = [
            e
            for k in (1, 2)
            for e in itertools.islice(combinations(world.space, task.scene, k), 60)
        ]
        scenes += world.apply_batch(task.scene, edits)
        scenes += list(world.demonstrate(task).scenes)
    got = world.render_batch(scenes)  # (B, H, W, 3)
    with world.layouts.lock:
        for scene, frame in zip(scenes, got, strict=True):
            env, _ = world.layouts.restore(scene)
            want = env.get_frame(
                highlight=env.highlight, tile_size=world.tile, agent_pov=world.view == "partial"
            )
            np.testing.assert_array_equal(frame, want)


def test_stepping_is_the_environments_own_step(world):
    """Random actions through the wrapped environment and through the world's step give the
    same frames at every step, and the same reward."""
    env = world.make_env()
    rng = np.random.default_rng(0)
    for seed in range(2):
        obs, _ = env.reset(seed=seed)
        scene = world.train_task(seed).scene
        for t in range(40):
            a = int(rng.integers(world.action_dim))
            obs, reward, terminated, truncated, _ = env.step(a)
            scene = world.step_batch([scene], np.array([a]))[0]
            np.testing.assert_array_equal(world.render(scene), obs, err_msg=f"step {t}")
            assert (scene.agent[6] > 0) == (reward > 0) or scene.agent[6] > 0
            if terminated or truncated:
                assert world.done(scene)
                break


def test_a_step_does_not_depend_on_what_was_stepped_before(world):
    """The environment's objects are shared between scenes of a layout: stepping one scene
    must not leak into the next (an absent object keeps the look and place of its scene)."""
    fresh = MiniGridWorld(world.env_id, tile=world.tile, view=world.view)
    step = MiniGridWorld.step_one.__wrapped__  # past the cache: really stepped
    scenes = [world.test_task(shift, s).scene for shift in world.shifts for s in range(2)]
    rng = np.random.default_rng(1)
    for scene in scenes:  # churn: other scenes of other layouts, random actions
        for _ in range(5):
            scene = step(world, scene, int(rng.integers(world.action_dim)))
    for scene in scenes:
        for a in range(world.action_dim):
            assert step(world, scene, a) == step(fresh, scene, a)


def test_the_concept_space_is_read_from_the_grids():
    world = sim.get_world("minigrid:MiniGrid-DoorKey-5x5-v0")
    names = [s.name for s in world.space.slots]
    assert {"key0", "door0", "goal0"} <= set(names) and world.distractor in names
    key = world.space.slot("key0")
    assert key.kind == "key" and set(key.concept("colour").values) == {
        "red",
        "green",
        "blue",
        "purple",
        "yellow",
        "grey",
    }
    assert world.space.slot(world.distractor).optional  # the extra ball can be added
    lava = sim.get_world("minigrid:MiniGrid-LavaGapS5-v0").space
    lava_slots = [s for s in lava.slots if s.kind == "lava"]
    assert lava_slots and all(len(s.concept("colour").values) == 1 for s in lava_slots)
    fetch = sim.get_world("minigrid:MiniGrid-Fetch-5x5-N2-v0").space
    assert len([s for s in fetch.slots if s.kind in ("key", "ball")]) >= 2


def test_the_expert_solves_training_and_shifted_tasks(world):
    tasks = [world.train_task(s) for s in range(3)]
    tasks += [world.test_task(shift, s) for shift in world.shifts for s in range(2)]
    for task in tasks:
        assert world.demonstrate(task).success, (task.shift, task.seed)


def test_shifts_change_what_their_kind_says(world):
    for seed in range(3):
        if "object_ti" not in world.shifts:
            break
        obj = world.test_task("object_ti", seed)
        base = world.layout_scene(int(obj.scene.agent[0]))
        changed = [
            (o.slot, o.value("colour"), b.value("colour"))
            for o, b in zip(obj.scene.objects, base.objects, strict=True)
            if o.present and o.values != b.values
        ]
        assert 1 <= len(changed) <= 2 and obj.cause[0] in {c[0] for c in changed}
        assert obj.scene.agent == base.agent
        assert not any(obj.reward.is_relevant(c[0], "colour") for c in changed)
    for seed in range(3):
        dist = world.test_task("distractor_ti", seed)
        assert dist.cause == (world.distractor, PRESENCE)
        assert dist.scene.obj(world.distractor).present
        other = world.test_task("other", seed)
        start = world.layout_scene(int(other.scene.agent[0]))
        assert other.scene.objects == start.objects and other.scene.agent[1:4] != start.agent[1:4]
    with pytest.raises(UserError, match="makes no object_tr tasks"):
        world.test_task("object_tr", 0)


def test_fresh_tasks_carry_the_shift(world):
    task = world.test_task("object_ti" if "object_ti" in world.shifts else "distractor_ti", 0)
    slot = task.cause[0]
    value = task.scene.obj(slot).value("colour")
    for fresh in world.fresh_tasks(task, 5, seed=0, shifted=True):
        assert fresh.scene.obj(slot).value("colour") == value
        assert fresh.scene.obj(slot).present


def test_the_experts_plans_earn_the_stock_environments_reward(world):
    """The expert's actions, found by stepping restored scenes (a BabyAI level's instruction
    follows each restored scene), replayed in the stock environment reach its reward."""
    env = world.make_env()
    for seed in range(2):
        demo = world.demonstrate(world.train_task(seed))
        assert demo.success
        env.reset(seed=seed)
        rewards = []
        for a in demo.actions:
            _, reward, terminated, truncated, _ = env.step(int(a))
            rewards.append(reward)
            if terminated or truncated:
                break
        assert max(rewards) > 0


def test_a_scene_without_a_plan_is_searched_once_in_a_demonstration():
    """An unsolvable scene (DoorKey with its key removed): the expert idles for the whole
    horizon, and the scenes it idles through (the same but for the step count) reuse the
    first search's answer instead of searching again."""
    w = sim.get_world("minigrid:MiniGrid-DoorKey-5x5-v0")
    task = w.train_task(0)
    keyless = task.with_scene(
        w.apply(task.scene, Edit.of(Change("key0", PRESENCE, PRESENT, ABSENT)))
    )
    searched = []
    search = w.planner._search
    w.planner._search = lambda scene, thorough=True: (
        searched.append(scene) or search(scene, thorough)
    )
    try:
        demo = w.demonstrate(keyless)
    finally:
        del w.planner._search
    assert not demo.success and len(demo.actions) == w.horizon
    assert len(searched) == 1


def test_babyai_levels_of_one_instruction_are_worlds():
    """Their missions read like MiniGrid's; the expert's plans, found by stepping restored
    scenes (the instruction's verifier follows each one: where its objects are, what was
    carried before the step), earn the stock level's reward, a PutNext's drop included."""
    for env_id in ("BabyAI-GoToRedBallNoDists-v0", "BabyAI-OpenRedDoor-v0"):
        w = sim.get_world(f"minigrid:{env_id}")
        task = w.test_task(w.shifts[0], 0)
        assert w.demonstrate(task).success
    put = sim.get_world("minigrid:BabyAI-PutNextS4N1-v0")
    assert put.train_task(0).reward.is_relevant("key0", "colour")
    test_the_experts_plans_earn_the_stock_environments_reward(put)
    with pytest.raises(UserError, match="sequences") as err:
        sim.get_world("minigrid:BabyAI-GoToSeqS5R2-v0")
    assert "\n" not in str(err.value)


def test_empty_cells_outside_the_rooms_are_not_free():
    """MultiRoom leaves empty cells outside its rooms: no shift puts the agent or a ball
    there (the agent would walk off the grid)."""
    w = sim.get_world("minigrid:MiniGrid-MultiRoom-N2-S4-v0")
    for seed in range(3):
        other = w.test_task("other", seed)
        assert w.demonstrate(other).success
        dist = w.test_task("distractor_ti", seed)
        assert w.demonstrate(dist).success


def test_large_frames_are_refused_before_they_are_drawn():
    with pytest.raises(UserError, match="give tile=10 or less") as err:
        sim.get_world("minigrid:MiniGrid-MultiRoom-N6-v0:tile=64")
    assert "\n" not in str(err.value) and "1600x1600" in str(err.value)
    w = sim.get_world("minigrid:MiniGrid-MultiRoom-N6-v0:tile=10")  # the tile it names fits
    assert w.obs_shape == (250, 250, 3)


def test_what_large_frames_cost_is_said_once():
    w = sim.get_world("minigrid:MiniGrid-MultiRoom-N2-S4-v0")
    lines = [line for line in w.notes(w.train_task(0)) if "KiB each" in line]
    assert len(lines) == 1 and "200x200" in lines[0] and "search step" in lines[0]
    small = sim.get_world("minigrid:MiniGrid-DoorKey-5x5-v0")
    assert not any("KiB each" in line for line in small.notes(small.train_task(0)))


def test_a_batch_of_frames_takes_its_own_memory_and_one_chunk():
    """581 frames of 250x250 (MultiRoom-N6 at tile 10) rendered at once in a fresh process:
    the peak grows by the batch and a chunk, not twice the batch."""
    code = """
import sim

def peak():  # this process's high-water mark since its exec (ru_maxrss keeps the parent's)
    return int(open("/proc/self/status").read().split("VmHWM:")[1].split()[0]) * 1024

w = sim.get_world("minigrid:MiniGrid-MultiRoom-N6-v0:tile=10")
scenes = ([w.layout_scene(s) for s in range(5)] * 200)[:581]
w.render_batch(scenes[:2])
before = peak()
frames = w.render_batch(scenes)
after = peak()
print(frames.nbytes, after - before)
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600
    )
    nbytes, grown = (int(v) for v in out.stdout.split())
    assert nbytes == 581 * 250 * 250 * 3
    assert grown < 1.5 * nbytes, (grown, nbytes)


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("minigrid:MiniGrid-Nope-v0", "not a registered MiniGrid or BabyAI environment"),
        ("minigrid:CartPole-v1", "not a registered MiniGrid or BabyAI environment"),
        ("minigrid:MiniGrid-DoorKey-5x5-v0:tile=0", "unknown option 'tile=0'"),
        ("minigrid:MiniGrid-DoorKey-5x5-v0:view=top", "unknown option 'view=top'"),
    ],
)
def test_bad_minigrid_names_are_one_line(name, message):
    with pytest.raises(UserError, match=message) as err:
        sim.get_world(name)
    assert "\n" not in str(err.value)
    assert "CartPole-v1" in gymnasium.registry  # a real id, only not a MiniGrid one
