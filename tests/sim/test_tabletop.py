"""Tabletop: the env contract, concept space, rendering of every shape and colour, tasks."""

from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sim
from sim.core import (
    ABSENT,
    PRESENCE,
    PRESENT,
    SHIFTS,
    Change,
    Edit,
    Obj,
    UserError,
    single_changes,
)
from sim.tabletop import tasks as TK
from sim.tabletop.catalogue import GOALS, MANIPULATED, SHAPES
from sim.tabletop.colours import (
    ALL_COLOURS,
    DEFAULT_COLOURS,
    PLAIN_RGB,
    TABLE_RGB,
    TEXTURES,
)
from sim.tabletop.env import TabletopEnv
from sim.tabletop.world import TabletopWorld

SEEDS = range(6)


@pytest.fixture(scope="module")
def world():
    return sim.get_world("tabletop")


def _alone(world, shape: str, colour: str, xy=(0.0, 0.0)):
    """A scene showing only the object (the goal waits off camera, on the table's rim)."""
    scene = TK.make_scene((shape, colour), ("frame", "blue"))
    scene = scene.with_obj(Obj("object", True, scene.obj("object").values, TK.pose(xy)))
    return scene.with_obj(Obj("goal", True, scene.obj("goal").values, TK.pose((0.5, 0.5))))


def _object_mask(frame: np.ndarray) -> np.ndarray:
    """bool (H, W): pixels that are not the bare table."""
    return np.abs(frame.astype(int) - np.array(TABLE_RGB)).sum(-1) > 6


# -- the environment ------------------------------------------------------------------------------
def test_check_env_passes(world):
    env = TabletopEnv(world=world)
    check_env(env, skip_render_check=True)
    assert env.observation_space.shape == (80, 80, 3)
    assert env.action_space.shape == (4,)


def test_registered_and_reset_to_a_task(world):
    env = gym.make("dfa/Tabletop-v0")
    task = world.test_task("object_tr", 1)
    obs, info = env.reset(options={"task": task})
    assert obs.dtype == np.uint8 and obs.shape == (80, 80, 3)
    assert np.array_equal(obs, world.render(task.scene))
    obs, reward, terminated, truncated, info = env.step(world.expert_action(task, task.scene))
    assert terminated and not truncated and info["success"] and reward > -0.1
    env.close()


def test_importing_sim_does_not_load_mujoco():
    code = (
        "import sys, sim; w = sim.get_world('tabletop'); w.test_task('other', 0); "
        "heavy = [m for m in sys.modules if m.split('.')[0] in ('mujoco', 'trimesh', 'shapely')]; "
        "assert not heavy, heavy"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# -- the concept space ----------------------------------------------------------------------------
def test_concept_space_sizes(world):
    assert len(SHAPES) == 29 and len(MANIPULATED) == 19 and len(GOALS) == 6
    assert len(PLAIN_RGB) == 17 and len(TEXTURES) == 65 and len(ALL_COLOURS) == 82
    assert world.colours == DEFAULT_COLOURS and len(DEFAULT_COLOURS) == 81
    assert world.space.dim == 4 * (29 + 81)
    assert [s.optional for s in world.space.slots] == [False, False, True, True]


def test_dark_colours_follow_vima():
    assert PLAIN_RGB["dark blue"] == (42, 66, 90)  # HSV value of (78, 121, 167) lowered by 0.3
    assert "dark olive" not in PLAIN_RGB


def test_encode_decode_round_trip(world):
    scenes = [world.train_task().scene] + [
        world.test_task(s, k).scene for s in SHIFTS for k in SEEDS
    ]
    after = world.step_batch(
        scenes[:3], np.stack([world.expert_action(None, s) for s in scenes[:3]])
    )
    for s in scenes + after:
        phi = world.space.encode(s)
        assert phi.shape == (440,) and phi.sum() == 2 * sum(o.present for o in s.objects)
        assert world.space.decode(phi, s) == s


# -- rendering ------------------------------------------------------------------------------------
def test_every_shape_renders_visible_and_distinct(world):
    frames = world.render_batch([_alone(world, s, "red") for s in SHAPES])  # (29, 80, 80, 3)
    masks = np.stack([_object_mask(f) for f in frames])
    areas = masks.sum(axis=(1, 2))
    assert areas.min() >= 4, dict(zip(SHAPES, areas.tolist(), strict=True))
    for i in range(len(SHAPES)):
        for j in range(i + 1, len(SHAPES)):
            differ = int((masks[i] ^ masks[j]).sum())
            assert differ >= 4, f"{SHAPES[i]} and {SHAPES[j]} look alike ({differ} px differ)"


def test_every_colour_renders_visible_and_distinct(world):
    frames = world.render_batch([_alone(world, "round", c) for c in ALL_COLOURS])
    disc = _object_mask(frames[0])  # the same footprint in every frame
    assert disc.sum() > 100
    crops = frames[:, disc].astype(float)  # (82, N, 3)
    table_gap = dict(
        zip(ALL_COLOURS, np.abs(crops - np.array(TABLE_RGB)).mean(axis=(1, 2)), strict=True)
    )
    # granite, left out of the default list, is the one that comes close to the grey table
    assert min(table_gap[c] for c in DEFAULT_COLOURS) > 15, table_gap
    assert table_gap["granite"] > 3
    for i in range(len(ALL_COLOURS)):
        gaps = np.abs(crops[i + 1 :] - crops[i]).mean(axis=(1, 2))
        if len(gaps):
            j = int(np.argmin(gaps))
            assert gaps[j] > 3, f"{ALL_COLOURS[i]} and {ALL_COLOURS[i + 1 + j]} look alike"


def test_plain_colours_render_as_their_rgb(world):
    frames = world.render_batch([_alone(world, "block", c) for c in PLAIN_RGB])
    centre = frames[:, 38:42, 38:42].reshape(len(PLAIN_RGB), -1, 3).astype(int)  # top face
    for name, px in zip(PLAIN_RGB, centre, strict=True):
        assert np.abs(px - np.array(PLAIN_RGB[name])).max() <= 3, (name, px[0])


def test_rendering_is_deterministic_and_edits_in_place(world):
    a, b = world.test_task("distractor_ti", 0).scene, world.test_task("object_tr", 2).scene
    first = world.render_batch([a, b, a, b])
    assert np.array_equal(first[0], first[2]) and np.array_equal(first[1], first[3])
    assert not np.array_equal(first[0], first[1])
    edit = Edit.of(Change("distractor0", PRESENCE, PRESENT, ABSENT))
    removed = world.render(world.apply(a, edit))
    assert np.array_equal(
        removed, world.render(a.with_obj(Obj("distractor0", False, *_rest(a, "distractor0"))))
    )


def _rest(scene, slot):
    o = scene.obj(slot)
    return o.values, o.pos


# -- tasks ----------------------------------------------------------------------------------------
def test_training_task_layout(world):
    t = world.train_task(0)
    assert t.scene.obj("object").pos[:2] == TK.AREAS["top-left"]
    assert t.scene.obj("goal").pos[:2] == TK.AREAS["bottom-right"]
    layouts = set()
    for seed in range(10):  # the ten demonstrations the base policy is cloned on
        t = world.train_task(seed)
        assert t == world.train_task(seed)
        assert not t.scene.obj("distractor0").present and not t.scene.obj("distractor1").present
        assert t.scene.obj("object").value("shape") in MANIPULATED
        assert t.scene.obj("goal").value("shape") in GOALS
        areas = (TK._area_of(t.scene.obj("object")), TK._area_of(t.scene.obj("goal")))
        assert areas[0] != areas[1] and TK.UNSEEN_AREA not in areas
        assert t.scene == TK.make_scene(obj_area=areas[0], goal_area=areas[1])
        layouts.add(areas)
    # they cover every training layout: the object and the goal each visit all four quadrants
    assert layouts == set(TK.TRAIN_LAYOUTS)
    assert {a for a, _ in layouts} == {g for _, g in layouts} == set(TK.QUADRANTS)


def test_shifts_follow_the_reward_conventions(world):
    for seed in range(12):
        for shift in SHIFTS:
            t = world.test_task(shift, seed)
            assert t == world.test_task(shift, seed)
            r = t.reward
            if shift.startswith("object"):
                slot, concept = t.cause
                value = t.scene.obj(slot).value(concept)
                train_value = world.train_task().scene.obj(slot).value(concept)
                assert value != train_value
                if concept == "shape":
                    assert value in (MANIPULATED if slot == "object" else GOALS)
                if shift == "object_ti":
                    assert not r.is_relevant(slot, concept)
                    assert len(r.allowed_values(slot, concept)) > 1
                else:
                    assert r.is_relevant(slot, concept)
                    assert r.allowed_values(slot, concept) == (value,)
            elif shift.startswith("distractor"):
                assert t.cause == ("distractor0", PRESENCE) and t.scene.obj("distractor0").present
                if shift == "distractor_ti":
                    assert not r.is_relevant("distractor0", PRESENCE)
                    assert r.allowed_values("distractor0", PRESENCE) == (PRESENT, ABSENT)
                else:
                    assert r.is_relevant("distractor0", PRESENCE) and "distractor0" in r.avoid
                    assert r.allowed_values("distractor0", PRESENCE) == (PRESENT,)
            else:
                assert t.cause is None
                areas = [TK._area_of(o) for o in t.scene.objects[:2]]
                assert areas.count(TK.UNSEEN_AREA) == 1  # one moved where training never went
                assert any(a in layout for layout in TK.TRAIN_LAYOUTS for a in areas)
            if shift != "other":
                layout = (TK._area_of(t.scene.obj("object")), TK._area_of(t.scene.obj("goal")))
                assert layout in TK.TRAIN_LAYOUTS


def test_fresh_tasks_can_take_the_training_layouts(world):
    task = world.test_task("object_ti", 1)
    moved = world.fresh_tasks(task, 16, seed=5, layouts="train")
    layouts = {
        (TK._area_of(f.scene.obj("object")), TK._area_of(f.scene.obj("goal"))) for f in moved
    }
    assert layouts <= set(TK.TRAIN_LAYOUTS) and len(layouts) >= 4
    for a, b in zip(world.fresh_tasks(task, 16, seed=5), moved, strict=True):
        assert [o.values for o in a.scene.objects] == [o.values for o in b.scene.objects]


def test_fresh_tasks_draw_from_the_reward(world):
    for shift in SHIFTS:
        task = world.test_task(shift, 1)
        fresh = world.fresh_tasks(task, 8, seed=5)
        assert fresh == world.fresh_tasks(task, 8, seed=5)
        for f in fresh:
            assert f.reward == task.reward
            for slot, concept, values in task.reward.allowed:
                o = f.scene.obj(slot)
                got = (
                    (PRESENT if o.present else ABSENT) if concept == PRESENCE else o.value(concept)
                )
                assert got in values
            xy = [o.pos[:2] for o in f.scene.objects if o.present]
            assert len(set(xy)) == len(xy)  # one object per area


def test_placements_keep_clear_of_the_demonstration(world):
    task = world.test_task("distractor_ti", 0)
    demo = world.demonstrate(task)
    spots = world.placements(task, "distractor1", demo)
    assert spots
    for p in spots:
        for a in demo.actions:
            assert np.hypot(p[0] - a[0], p[1] - a[1]) >= TK.CLEAR_M
            assert np.hypot(p[0] - a[2], p[1] - a[3]) >= TK.CLEAR_M
        for s in demo.scenes:
            for o in s.objects:
                if o.present and o.slot != "distractor1":
                    assert np.hypot(p[0] - o.pos[0], p[1] - o.pos[1]) >= TK.CLEAR_M


def test_rendering_from_other_threads(world):
    scenes = [world.test_task("object_ti", k).scene for k in range(6)]
    expected = world.render_batch(scenes)
    with ThreadPoolExecutor(3) as pool:
        frames = list(pool.map(world.render, scenes))
    assert np.array_equal(np.stack(frames), expected)
    assert np.array_equal(world.render(scenes[0]), expected[0])


def test_colour_list_is_configurable():
    small = TabletopWorld(colours=("red", "blue", "green", "tiger"))
    assert small.space.dim == 4 * (29 + 4)
    assert small.test_task("object_ti", 0).scene.obj("object").value("colour") in small.colours
    with pytest.raises(UserError, match="unknown colours"):
        TabletopWorld(colours=("red", "blue", "mauve"))


def test_every_single_edit_renders_in_one_batch(world):
    """The 434 single edits of a scene with both distractors in one batch: a frame per scene,
    the one that scene renders alone (how fast, per scene, is `dfa bench`'s figure)."""
    base = world.test_task("distractor_ti", 1).scene
    presence, values = single_changes(world.space, base)
    scenes = [world.apply(base, Edit.of(c)) for c in presence + values]
    frames = world.render_batch(scenes)  # (434, 80, 80, 3) uint8
    assert frames.shape == (len(scenes), *world.obs_shape) == (434, 80, 80, 3)
    assert frames.dtype == np.uint8
    for i in range(0, len(scenes), 48):
        assert np.array_equal(frames[i], world.render(scenes[i])), str(scenes[i])
