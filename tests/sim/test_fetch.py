"""Fetch worlds: the environment's own frames, steps and success, a concept space read from its
model, shifts that every scripted demonstration solves, and one line for what is not a Fetch
task."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import sim
from sim.core import SHIFTS
from sim.fetch.world import CAMERA, register_robotics

PICK = "fetch:FetchPickAndPlace-v4"
STEP_S = 0.04  # one Fetch step: 20 physics steps of 2 ms


@pytest.fixture(scope="module")
def world():
    return sim.get_world(PICK)


def _stock(env_id: str, camera: dict = CAMERA):
    """The environment as gymnasium makes it, with the same camera."""
    register_robotics()
    return gymnasium.make(
        env_id, render_mode="rgb_array", width=84, height=84, default_camera_config=camera
    ).unwrapped


def _render(stock) -> np.ndarray:
    """The stock environment's render(), its GL context made current first (the world's
    renderer lets its own go after each batch)."""
    stock.mujoco_renderer._get_viewer("rgb_array").make_context_current()
    return stock.render()


def _stock_views(stock, others) -> np.ndarray:
    """The stock environment's render() beside that of a stock environment built with each of
    the world's extra views as its camera, put in the same state: what the world's frame
    holds."""
    import mujoco

    frames = [_render(stock)]
    for other in others:
        other.data.qpos[:], other.data.qvel[:] = stock.data.qpos, stock.data.qvel
        other.data.mocap_pos[:], other.data.mocap_quat[:] = (
            stock.data.mocap_pos,
            stock.data.mocap_quat,
        )
        other.goal = stock.goal.copy()
        mujoco.mj_forward(other.model, other.data)
        frames.append(_render(other))
    return np.concatenate(frames, axis=1)


def test_the_concept_space_is_read_from_the_model(world):
    slots = {s.name: s for s in world.space.slots}
    assert list(slots) == ["object", "target", "table", "distractor0"]
    assert world.built == {
        "object": "dark grey",  # Fetch's block_mat
        "target": "red",  # its target0 site
        "table": "light grey",  # its table_mat
        "distractor0": "blue",
    }
    assert slots["distractor0"].optional and not slots["object"].optional
    reach = sim.get_world("fetch:FetchReach-v4")
    assert [s.name for s in reach.space.slots] == ["target", "table", "distractor0"]


@pytest.mark.parametrize(
    "env_id, steps",
    [
        ("FetchPickAndPlace-v4", 50),
        ("FetchPush-v4", 50),
        ("FetchSlide-v4", 15),
        ("FetchReach-v4", 50),
    ],
)
def test_a_rollout_in_dfa_is_the_environments_own(env_id, steps):
    """From the same reset, the stock environment, run as an image policy runs it (render,
    act, step), and the world step the same actions to the same states and the same success
    (the world's model only adds a parked distractor that touches nothing), and draw the same
    frames of the same state.

    The distractor's six degrees of freedom change the last bits of MuJoCo's sums (1e-16);
    Slide's struck, spinning puck amplifies them (to 1e-3 m within ten steps of the strike), so
    its rollouts are compared up to the strike (15 steps), the others' to the end."""
    world = sim.get_world(f"fetch:{env_id}")
    stock = _stock(env_id)
    others = [_stock(env_id, view) for view in world.extra_views]
    for seed in (3, 4):
        stock.reset(seed=seed)
        like = world.sample_scene(0)  # (a reset of the world's own environment)
        scene = world.scene_of(stock_state_into(world, stock), 0, like)
        task = world.task_for(scene)
        rng = np.random.default_rng(seed)
        for t in range(steps):
            a = world.expert_action(task, scene) + rng.normal(0, 0.2, 4).astype(np.float32)
            a = np.clip(a, -1, 1).astype(np.float32)
            frame = _stock_views(stock, others)  # an image policy's loop: render, act, step
            if t % 10 == 0:
                same = world.scene_of(stock_state_into(world, stock), t, like)
                np.testing.assert_array_equal(world.render(same), frame)
            _, _, _, _, info = stock.step(a)
            scene = world.step_batch([scene], a[None])[0]
            here = world.restore(scene).data
            n = stock.model.nq
            np.testing.assert_allclose(here.qpos[:n], stock.data.qpos, rtol=0, atol=1e-9)
            np.testing.assert_allclose(here.qvel[: stock.model.nv], stock.data.qvel, atol=1e-8)
            assert world.succeeds(scene) == bool(info["is_success"])


def stock_state_into(world, stock):
    """The world's environment put in the stock environment's state: its model is the stock
    one with the distractors' bodies appended, so the stock state is a prefix of its own."""
    import mujoco

    env = world.restore(world.sample_scene(0))
    m, d = stock.model, stock.data
    assert [env.model.joint(i).name for i in range(m.njnt)] == [
        m.joint(i).name for i in range(m.njnt)
    ]
    env.data.qpos[: m.nq] = d.qpos
    env.data.qvel[: m.nv] = d.qvel
    env.data.qacc_warmstart[: m.nv] = d.qacc_warmstart
    env.data.ctrl[:] = d.ctrl
    env.data.mocap_pos[:] = d.mocap_pos
    env.data.mocap_quat[:] = d.mocap_quat
    env.data.time = d.time
    env.goal = stock.goal.copy()
    mujoco.mj_forward(env.model, env.data)
    return env


def test_frames_are_the_environments_render_in_every_look(world):
    scenes = [world.test_task(shift, s).scene for shift in SHIFTS for s in range(2)]
    ours = world.render_batch(scenes)
    theirs = np.stack([world.restore(s).render() for s in scenes])
    assert np.array_equal(ours[:, :, :84], theirs)  # the environment's own camera first
    recoloured = world.test_task("object_ti", 0)
    assert not np.array_equal(
        world.render(recoloured.scene), world.render(world.train_task(0).scene)
    )


def test_painting_a_named_colour_draws_that_colour_and_any_other_draws_a_new_look(world):
    scene = world.train_task(3).scene
    table = scene.obj("table")
    named = [scene.with_obj(table.with_value("colour", c)) for c in ("green", "purple")]
    rgb = world.paints.rgb
    painted = world.render_painted(
        [scene, scene, scene], [{"table": rgb["green"]}, {"table": rgb["purple"]}, {}]
    )
    assert world.paints.concept == "colour" and set(rgb) <= set(
        world.space.values("table", "colour")
    )
    assert np.array_equal(painted[:2], world.render_batch(named))  # the same rgba, the same pixels
    assert np.array_equal(painted[2], world.render(scene))  # nothing painted: as drawn
    between = world.render_painted([scene], [{"table": (0.3, 0.6, 0.9)}])[0]
    changed = (between != painted[2]).any(-1)
    assert 0.2 < changed.mean() < 0.9  # the table's pixels, not the whole frame
    assert np.array_equal(world.render(scene), painted[2])  # the paint does not stay


def test_every_shift_is_solved_by_the_expert_and_carries_its_cause(world):
    for shift in SHIFTS:
        for seed in range(3):
            task = world.test_task(shift, seed)
            assert world.demonstrate(task).success, (shift, seed, task.reward.instruction)
            if shift == "other":
                assert task.cause is None
            elif shift.startswith("distractor"):
                assert task.scene.obj("distractor0").present
            else:
                slot, concept = task.cause
                assert task.scene.obj(slot).value(concept) != world.built[slot]


def test_no_task_hides_one_slot_in_the_colour_of_another(world):
    """A table in the target's red hides the target from the camera; a block in the cube's grey
    is a second cube: R' accepts neither, so no fresh task or variant shows one."""
    slots = [s.name for s in world.slot_specs]
    for shift in ("object_ti", "distractor_ti"):
        for seed in range(6):
            task = world.test_task(shift, seed)
            for fresh in world.fresh_tasks(task, 20, seed):
                shown = [(o.slot, o.value("colour")) for o in fresh.scene.objects if o.present]
                for slot, colour in shown:
                    others = {world.built[s] for s in slots if s != slot}
                    assert colour not in others, (shift, seed, slot, colour)


def test_a_distractor_starts_where_the_scene_says_and_waits_out_of_view_when_absent(world):
    task = world.test_task("distractor_ti", 0)
    env = world.restore(task.scene)
    np.testing.assert_allclose(
        env.data.body("distractor0").xpos, task.scene.obj("distractor0").pos[:3]
    )
    absent = world.train_task(0).scene
    frames_without = world.render(absent)
    env = world.restore(absent)
    assert env.data.body("distractor0").xpos[1] < -1.0  # parked far to the side
    moved = world.step_batch([absent], np.zeros((1, 4), np.float32))[0]
    assert moved.agent[world.head :] != absent.agent[world.head :]
    assert frames_without.shape == (84, 168, 3)  # the side view, the front view beside it


def test_the_striking_expert_slides_the_puck_onto_the_target():
    """FetchSlide's demonstrator strikes the puck and lets it slide to the goal (it does so on
    17 of the 20 training tasks of seeds 0-19; seed 0's goal, 0.75 m off, is further than its
    strikes carry the puck in the time left)."""
    world = sim.get_world("fetch:FetchSlide-v4")
    for seed in (1, 3):
        task = world.train_task(seed)
        demo = world.demonstrate(task)
        assert demo.success, seed
        puck = np.array([s.obj("object").pos[:2] for s in demo.scenes])  # (T+1, 2)
        grip = np.array([world.restore(s).data.site("robot0:grip").xpos[:2] for s in demo.scenes])
        speed = np.linalg.norm(np.diff(puck, axis=0), axis=1) / STEP_S  # (T,) m/s
        free = np.linalg.norm(grip[1:] - puck[1:], axis=1) > 0.1
        assert np.linalg.norm(puck[-1] - puck[0]) > 0.2  # it went far
        assert (speed[free] > 0.3).any()  # sliding on its own, well clear of the gripper


def test_the_pick_and_place_expert_grips_through_the_noise_its_demonstrations_execute(world):
    """With noise of the cloning's scale on what it executes, the gripper ends a few mm off the
    block: the expert still goes down and grips (it hovered over the block for good before
    LINED_UP_M: 26 of the 200 noisy training demonstrations succeeded, 195 after)."""
    noise = world.cloning.noise
    solved = [world.demonstrate(world.train_task(s), noise=noise, seed=s).success for s in range(6)]
    assert sum(solved) >= 5, solved
