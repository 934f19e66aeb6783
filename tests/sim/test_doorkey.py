"""DoorKey: the env contract, rendering, dynamics and expert (tasks: test_doorkey_tasks.py)."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from minigrid.core.grid import Grid
from minigrid.core.world_object import Lava

import sim
from sim.core import PRESENCE, SHIFTS, Edit, Obj, Scene, Trajectory, single_changes
from sim.doorkey.env import DoorKeyEnv
from sim.doorkey.layout import (
    CLOSED,
    FORWARD,
    LOCKED,
    OBJ_COLOURS,
    OPEN,
    PICKUP,
    TILE_PX,
    TOGGLE,
    agent_tuple,
    parse,
)
from sim.doorkey.objects import PinkLava, build_grid
from sim.doorkey.world import DoorKeyWorld

SEEDS = range(4)


@pytest.fixture(scope="module")
def world() -> DoorKeyWorld:
    return DoorKeyWorld()


@pytest.fixture(scope="module")
def tasks(world):
    return [world.train_task()] + [world.test_task(s, seed) for s in SHIFTS for seed in SEEDS]


@pytest.fixture(scope="module")
def demos(world, tasks):
    return [world.demonstrate(t) for t in tasks]


def _with_agent(scene: Scene, col, row, d, carrying=False, door=LOCKED, t=0) -> Scene:
    return Scene(scene.world, scene.objects, agent_tuple(col, row, d, carrying, door, t))


def _with_lava(scene: Scene, slot: str, colour: str, cell) -> Scene:
    return scene.with_obj(Obj(slot, True, (("colour", colour),), (float(cell[0]), float(cell[1]))))


# -- the environment ------------------------------------------------------------------------------
def test_check_env_passes():
    env = gym.make("dfa/DoorKey-v0")
    assert env.observation_space == gym.spaces.Box(0, 255, (36, 36, 3), np.uint8)
    assert env.action_space == gym.spaces.Discrete(6)
    check_env(env.unwrapped)


def test_importing_sim_does_not_import_minigrid():
    code = "import sim, sys; sim.world_names(); assert 'minigrid' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_world_attributes(world):
    assert sim.get_world("doorkey").name == "doorkey"
    assert (world.discrete, world.action_dim, world.horizon) == (True, 6, 35)
    assert world.obs_shape == (36, 36, 3) and world.epsilon == 0.0 and world.lossless_frames


# -- determinism and round-trips ------------------------------------------------------------------
def test_same_seed_same_tasks_and_rollouts(world):
    for shift in SHIFTS:
        assert world.test_task(shift, 7) == world.test_task(shift, 7)
        a, b = (
            world.fresh_tasks(world.test_task(shift, 7), 3, seed=5),
            world.fresh_tasks(world.test_task(shift, 7), 3, seed=5),
        )
        assert a == b
    task = world.test_task("distractor_ti", 3)
    assert world.demonstrate(task).equals(world.demonstrate(task))
    runs = []
    for _ in range(2):
        env, rng = DoorKeyEnv(), np.random.default_rng(11)
        obs, _ = env.reset(seed=3, options={"task": task})
        frames = [obs]
        for _ in range(35):
            obs, _, term, trunc, _ = env.step(int(rng.integers(6)))
            frames.append(obs)
            if term or trunc:
                break
        runs.append((np.stack(frames), env.history))
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]


def test_encode_decode_round_trips(world, demos):
    for demo in demos:
        for scene in demo.scenes[::5]:
            phi = world.space.encode(scene)
            assert phi.dtype == np.uint8 and phi.shape == (world.space.dim,)
            assert world.space.decode(phi, scene) == scene
    scene = demos[0].scenes[0]
    presence, values = single_changes(world.space, scene)
    for change in presence + values:
        edited = world.apply(scene, Edit.of(change))
        assert world.space.decode(world.space.encode(edited), edited) == edited
        if change.concept == PRESENCE or scene.obj(change.slot).present:
            assert world.space.decode(world.space.encode(edited), scene) == edited


def test_trajectory_npz_round_trip(world, demos, tmp_path):
    for i, demo in enumerate(demos[:6]):
        back = Trajectory.load(demo.save(tmp_path / f"demo{i}.npz"))
        assert back.equals(demo) and back.actions.dtype == np.int64


# -- rendering ------------------------------------------------------------------------------------
def test_render_batch_equals_per_scene_and_env_render(world, demos):
    scenes = [s for d in demos for s in d.scenes[::3]]
    batch = world.render_batch(scenes)
    assert batch.shape == (len(scenes), 36, 36, 3) and batch.dtype == np.uint8
    assert np.array_equal(batch, np.stack([world.render(s) for s in scenes]))
    env = DoorKeyEnv()
    for scene in scenes[::7]:
        obs, _ = env.reset(options={"scene": scene})
        assert np.array_equal(obs, world.render(scene))
        assert np.array_equal(env.render(), world.render(scene))


def test_render_matches_minigrid_stock_grid_render(world, demos):
    """Every tile but the agent's is minigrid's own; the agent tile differs only in colour
    (white, not red), so its red channel is minigrid's too."""
    for demo in demos[::4]:
        for scene in demo.scenes[::4]:
            st = parse(scene)
            ours = world.render(scene)
            stock = Grid.render(build_grid(st), TILE_PX, st.agent, st.dir)
            ys, xs = st.row * TILE_PX, st.col * TILE_PX
            mask = np.ones((36, 36), bool)
            mask[ys : ys + TILE_PX, xs : xs + TILE_PX] = False
            assert np.array_equal(ours[mask], stock[mask])
            assert np.array_equal(ours[~mask][:, 0], stock[~mask][:, 0])
            assert not np.array_equal(ours[~mask], stock[~mask])  # the white agent


def test_pink_and_orange_lava_render_differently(world):
    assert Lava().encode() != PinkLava().encode()
    scene = world.train_task().scene
    orange = world.render(_with_lava(scene, "lava0", "orange", (8, 9)))
    pink = world.render(_with_lava(scene, "lava0", "pink", (8, 9)))
    tile = np.s_[27:30, 24:27]  # row 9, col 8
    assert not np.array_equal(orange[tile], pink[tile])
    assert np.array_equal(orange[:27], pink[:27])
    assert not np.array_equal(world.render(scene)[tile], orange[tile])


def test_carried_key_is_not_drawn(world):
    scene = world.train_task().scene
    carrying = _with_agent(scene, 1, 1, 0, carrying=True)
    kc, kr = (int(v) for v in scene.obj("key").pos)
    tile = np.s_[kr * 3 : kr * 3 + 3, kc * 3 : kc * 3 + 3]
    assert world.render(carrying)[tile].sum() < world.render(scene)[tile].sum()


# -- dynamics -------------------------------------------------------------------------------------
def test_step_batch_equals_env_step(world, tasks):
    rng = np.random.default_rng(0)
    env = DoorKeyEnv()
    for episode in range(60):
        task = tasks[episode % len(tasks)]
        _, info = env.reset(options={"task": task})
        scene = task.scene
        assert info["scene"] == scene
        while True:
            a = (
                int(world.expert_action(task, scene))
                if rng.random() < 0.5
                else int(rng.integers(6))
            )
            obs, _, term, trunc, info = env.step(a)
            scene = world.step_batch([scene], np.array([a]))[0]
            assert info["scene"] == scene
            assert np.array_equal(obs, world.render(scene))
            assert (term or trunc) == world.done(scene)
            if term or trunc:
                break


def test_step_batch_equals_env_step_from_random_states(world, tasks):
    """Mid-episode states facing the key, door, goal or lava, carrying or not, in any door
    state, then random actions."""
    rng = np.random.default_rng(2)
    env = DoorKeyEnv()
    vecs = ((1, 0), (0, 1), (-1, 0), (0, -1))
    for episode in range(200):
        task = tasks[episode % len(tasks)]
        st = parse(task.scene)
        targets = [st.key, st.goal, st.door_cell] + [c for c, _ in st.lava]
        taken = set(targets)
        tc, tr = targets[rng.integers(len(targets))]
        options = [
            (tc - dx, tr - dy, d)
            for d, (dx, dy) in enumerate(vecs)
            if 0 < tc - dx < 11
            and 0 < tr - dy < 11
            and tc - dx != 5
            and (tc - dx, tr - dy) not in taken
        ]
        if not options:
            continue
        col, row, d = options[rng.integers(len(options))]
        carrying, door = bool(rng.random() < 0.5), int(rng.integers(3))
        scene = _with_agent(task.scene, col, row, d, carrying, door, 20)
        env.reset(options={"scene": scene, "task": task})
        for a in rng.integers(6, size=15).tolist():
            obs, _, term, trunc, info = env.step(a)
            scene = world.step_batch([scene], np.array([a]))[0]
            assert info["scene"] == scene and np.array_equal(obs, world.render(scene))
            assert (term or trunc) == world.done(scene)
            if term or trunc:
                break


def test_batched_step_matches_single_steps(world, demos):
    scenes = [s for d in demos for s in d.scenes[::4]]
    actions = np.random.default_rng(1).integers(6, size=len(scenes))
    batch = world.step_batch(scenes, actions)
    assert batch == [
        world.step_batch([s], a[None])[0] for s, a in zip(scenes, actions, strict=True)
    ]


def test_lava_ends_the_episode_as_failure(world):
    task = world.train_task()
    scene = _with_lava(task.scene, "lava0", "pink", (2, 1))
    env = DoorKeyEnv()
    env.reset(options={"scene": scene, "task": task})
    _, reward, term, trunc, info = env.step(FORWARD)
    after = world.step_batch([scene], np.array([FORWARD]))[0]
    assert term and not trunc and reward == 0.0 and not info["success"]
    assert info["scene"] == after and world.done(after)
    assert world.step_batch([after], np.array([FORWARD]))[0] == after  # done: unchanged
    assert not world.success(task, [scene, after])


def test_any_key_opens_any_door(world):
    base = world.train_task().scene
    door_row = int(base.obj("door").pos[1])
    env = DoorKeyEnv()
    for key_c in OBJ_COLOURS:
        for door_c in OBJ_COLOURS:
            scene = base.with_obj(base.obj("key").with_value("colour", key_c))
            scene = scene.with_obj(scene.obj("door").with_value("colour", door_c))
            scene = _with_agent(scene, 4, door_row, 0, carrying=True, t=10)
            after = world.step_batch([scene], np.array([TOGGLE]))[0]
            assert parse(after).door == OPEN
            env.reset(options={"scene": scene})
            _, _, _, _, info = env.step(TOGGLE)
            assert info["scene"] == after
    # without a key the door stays locked; an unlocked door closes and opens again
    locked = _with_agent(base, 4, door_row, 0)
    assert parse(world.step_batch([locked], np.array([TOGGLE]))[0]).door == LOCKED
    opened = _with_agent(base, 4, door_row, 0, door=OPEN)
    closed = world.step_batch([opened], np.array([TOGGLE]))[0]
    assert parse(closed).door == CLOSED


def test_pickup_only_facing_the_key(world):
    scene = world.train_task().scene
    kc, kr = (int(v) for v in scene.obj("key").pos)
    facing = _with_agent(scene, kc, kr - 1, 1)
    assert parse(world.step_batch([facing], np.array([PICKUP]))[0]).carrying
    away = _with_agent(scene, kc, kr - 1, 3)
    assert not parse(world.step_batch([away], np.array([PICKUP]))[0]).carrying


# -- expert and tasks -----------------------------------------------------------------------------
def test_expert_solves_every_generated_layout(world, tasks, demos):
    fresh = [f for t in tasks[:: len(SEEDS)] for f in world.fresh_tasks(t, 4, seed=2)]
    for task, demo in zip(
        tasks + fresh, demos + [world.demonstrate(f) for f in fresh], strict=True
    ):
        assert demo.success, task.to_dict()
        final = parse(demo.scenes[-1])
        assert final.agent == final.goal and final.t <= 35
