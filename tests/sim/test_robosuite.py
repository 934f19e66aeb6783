"""robosuite worlds: the environment's own frames, steps and success, a concept space read from
its model, shifts that the scripted demonstrators solve, and one line for what is not offered."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import sim
from sim.core import UserError
from sim.robosuite.world import ARM, BUILD_SEED, CONTROL_HZ, SIZE_PX, import_robosuite, seeded

LIFT, STACK = "robosuite:Lift", "robosuite:Stack"


@pytest.fixture(scope="module")
def lift():
    return sim.get_world(LIFT)


@pytest.fixture(scope="module")
def stack():
    return sim.get_world(STACK)


def _stock(env_name: str, camera: str = "agentview"):
    """The environment as robosuite makes it (its default model, no distractor), with camera
    observations, the world's controller and control frequency."""
    robosuite = import_robosuite()
    from robosuite.controllers import load_composite_controller_config

    config = load_composite_controller_config(controller="BASIC", robot="Panda")
    config["body_parts"] = {ARM: config["body_parts"][ARM]}
    with seeded(BUILD_SEED):  # the world's model (e.g. Lift's cube size) is drawn so
        return robosuite.make(
            env_name,
            robots="Panda",
            controller_configs=config,
            has_renderer=False,
            has_offscreen_renderer=True,
            use_camera_obs=True,
            camera_names=camera,
            camera_heights=SIZE_PX,
            camera_widths=SIZE_PX,
            hard_reset=False,
            ignore_done=True,
            control_freq=CONTROL_HZ,
        )


def test_importing_sim_loads_neither_mujoco_nor_robosuite():
    code = (
        "import sys, sim; sim.check_world_name('robosuite:Lift'); "
        "heavy = [m for m in sys.modules if m.split('.')[0] in ('mujoco', 'robosuite')]; "
        "assert not heavy, heavy"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_concept_space_is_read_from_the_model(lift, stack):
    assert [s.name for s in lift.space.slots] == ["cube", "table", "distractor0"]
    assert [s.name for s in stack.space.slots] == ["cubeA", "cubeB", "table", "distractor0"]
    # robosuite's cubes and table are textured materials: no palette colour is theirs
    assert set(stack.built.values()) == {"as built", "blue"}
    assert stack.built["distractor0"] == "blue"
    assert "object_tr" not in lift.shifts and "object_tr" in stack.shifts
    assert lift.action_dim == 7 and lift.obs_shape == (84, 84, 3)


def _copy_into(world, stock) -> object:
    """The world's environment put in the stock environment's state: its model is the stock
    one with the distractor's body appended, so the stock state is a prefix of its own."""
    import mujoco

    env = world.restore(world.sample_scene(0))
    m, d = stock.sim.model._model, stock.sim.data._data
    wm, wd = world.physics(env)
    assert [wm.joint(i).name for i in range(m.njnt)] == [m.joint(i).name for i in range(m.njnt)]
    wd.qpos[: m.nq] = d.qpos
    wd.qvel[: m.nv] = d.qvel
    wd.qacc_warmstart[: m.nv] = d.qacc_warmstart
    wd.ctrl[:] = d.ctrl
    wd.mocap_pos[:] = d.mocap_pos
    wd.mocap_quat[:] = d.mocap_quat
    wd.time = d.time
    world.set_env_state(env, world.env_state(stock))
    mujoco.mj_forward(wm, wd)
    return env


def test_a_rollout_in_dfa_is_the_environments_own(lift):
    """From the same reset, the stock environment (its step, its camera) and the world step the
    same actions to the same states and the same success, and draw the same frames of the same
    state (robosuite's image rows come bottom first).

    The states agree to 1e-4, not bit for bit: the world's model has the parked distractor's
    six degrees of freedom beside the stock one's fifteen, which changes the last bits of
    MuJoCo's sums, and the grasp's contacts amplify them (measured: 2e-7 in this rollout, up
    to 1.3e-5 from other resets; a controller that kept a stale state was off by 5e-3)."""
    stock = _stock("Lift")
    with seeded(0):
        obs = stock.reset()
    like = lift.sample_scene(0)
    scene = lift.scene_of(_copy_into(lift, stock), 0, like)
    task = lift.task_for(scene)
    rng = np.random.default_rng(0)
    context = stock.sim._render_context_offscreen.gl_ctx
    lifted = 0
    for t in range(lift.horizon):
        if t % 10 == 0:  # the stock's camera, its state refreshed as its render() would
            same = lift.scene_of(_copy_into(lift, stock), t, like)
            np.testing.assert_array_equal(lift.render(same), obs["agentview_image"][::-1])
        a = lift.expert_action(task, scene) + rng.normal(0, 0.1, 7)
        a = np.clip(a, -1, 1)
        context.make_current()  # the world's renderer lets its own context go after a batch
        stock.step(a)
        # robosuite draws its observation before its last physics substep's derived
        # quantities (body poses) catch up with the state; forward() brings them up to date
        stock.sim.forward()
        obs = stock._get_observations(force_update=True)
        scene = lift.step_batch([scene], a[None])[0]
        _, here = lift.physics(lift.restore(scene))
        d = stock.sim.data._data
        np.testing.assert_allclose(here.qpos[: len(d.qpos)], d.qpos, rtol=0, atol=1e-4)
        np.testing.assert_allclose(here.qvel[: len(d.qvel)], d.qvel, rtol=0, atol=1e-4)
        assert lift.succeeds(scene) == bool(stock._check_success())
        lifted += lift.succeeds(scene)
    assert lifted > 0  # the noisy expert lifted the cube: the comparison saw both verdicts
    stock.close()


def test_the_expert_lifts_the_cube_in_every_shift(lift):
    for task in [lift.train_task(0), *(lift.test_task(s, 0) for s in lift.shifts)]:
        demo = lift.demonstrate(task)
        assert demo.success, (task.shift, task.reward.instruction)
        assert demo.scenes[-1].obj("cube").pos[2] > demo.scenes[0].obj("cube").pos[2] + 0.04


def test_the_expert_stacks_the_cubes_in_every_shift(stack):
    for task in [stack.train_task(0), *(stack.test_task(s, 1) for s in stack.shifts)]:
        demo = stack.demonstrate(task)
        assert demo.success, (task.shift, task.reward.instruction)
        if task.cause is not None:
            slot, concept = task.cause
            if slot != "distractor0":
                assert task.scene.obj(slot).value(concept) != stack.built[slot]


def test_shifts_change_what_the_camera_sees(lift):
    """A present distractor (drawn in a group robosuite's camera draws) and a recoloured
    table show; `other` puts the cube where the environment's own placement never does."""
    task = lift.test_task("distractor_ti", 0)
    absent = task.scene.with_obj(replace(task.scene.obj("distractor0"), present=False))
    assert not np.array_equal(lift.render(task.scene), lift.render(absent))
    _, data = lift.physics(lift.restore(absent))
    assert data.body("distractor0").xpos[1] < -1.0  # parked far to the side
    recoloured = lift.test_task("object_ti", 0)
    plain = recoloured.scene.with_obj(
        recoloured.scene.obj("table").with_value("colour", "as built")
    )
    assert not np.array_equal(lift.render(recoloured.scene), lift.render(plain))
    assert (
        lift.test_task("other", 0).scene.obj("cube").pos[1]
        > 0.1
        > max(abs(lift.train_task(s).scene.obj("cube").pos[1]) for s in range(3))
    )


@pytest.mark.parametrize(
    "name, said",
    [
        ("robosuite:Juggle", "not a robosuite task offered here; accepted: Lift, Stack"),
        ("robosuite:Lift:robot=Robby", "unknown option 'robot=Robby'; accepted: robot=Panda|"),
        ("robosuite:Lift:arm=left", "unknown option 'arm=left'"),
    ],
)
def test_what_is_not_offered_is_one_line(name, said):
    with pytest.raises(UserError, match=said.replace("|", r"\|")) as e:
        sim.get_world(name)
    assert "\n" not in str(e.value)


def test_one_click_on_the_cube_grasps_and_lifts_it(lift):
    from clicked import click_on, drawn

    task = lift.train_task(seed=0)
    cube = lift.effector_waypoint(
        task.scene, *click_on(lift, drawn(lift, task.scene, "cube"), 0), None
    )
    assert cube.grasp == "cube"
    demo = lift.follow(task, [cube])
    assert demo.success and demo.actions.shape == (lift.horizon, 7)
