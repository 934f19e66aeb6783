import gymnasium
import numpy as np
from gymnasium.utils.env_checker import check_env

from sim.core import SHIFTS


def test_check_env_passes():
    env = gymnasium.make("dfa/Nav2D-v0")
    check_env(env.unwrapped, skip_render_check=False)


def test_same_seed_same_rollout():
    runs = []
    for _ in range(2):
        env = gymnasium.make("dfa/Nav2D-v0")
        obs, _ = env.reset(seed=3)
        rng = np.random.default_rng(3)
        frames = [obs]
        for _ in range(20):
            obs, *_ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            frames.append(obs)
        runs.append(np.stack(frames))
    assert np.array_equal(*runs)


def test_render_is_deterministic_and_batched_equals_single(nav):
    scenes = [nav.test_task(s, i).scene for s in SHIFTS for i in range(3)]
    batch = nav.render_batch(scenes)
    assert batch.shape == (len(scenes), 36, 36, 3) and batch.dtype == np.uint8
    for scene, frame in zip(scenes, batch, strict=True):
        assert np.array_equal(nav.render(scene), frame)
    # the agent is white; a present object adds its own colour
    assert (batch[0] == 255).all(axis=-1).any()


def test_expert_lands_on_the_goal_for_every_shift(nav):
    for shift in SHIFTS:
        for seed in range(5):
            task = nav.test_task(shift, seed)
            demo = nav.demonstrate(task)
            assert demo.success, (shift, seed)
            assert demo.actions.shape == (20, 2)
    # the design's expert: 0.05 x (goal - start) per step on the training task
    demo = nav.demonstrate(nav.train_task())
    assert np.allclose(demo.actions, [0.5, -0.5])


def test_shift_generator_plants_its_cause(nav):
    for seed in range(5):
        train = nav.train_task().scene
        obj = nav.test_task("object_ti", seed)
        slot, concept = obj.cause
        assert obj.scene.obj(slot).value(concept) != train.obj(slot).value(concept)
        dis = nav.test_task("distractor_ti", seed)
        assert dis.scene.obj("distractor").present and dis.cause == ("distractor", "presence")
        other = nav.test_task("other", seed)
        assert other.cause is None and other.scene.obj("goal").pos != train.obj("goal").pos


def test_vectorised_step_matches_single_steps(nav):
    rng = np.random.default_rng(0)
    scenes = [nav.test_task("distractor_ti", i).scene for i in range(8)]
    actions = rng.uniform(-1.5, 1.5, (8, 2))
    batched = nav.step_batch(scenes, actions)
    single = [nav.step_batch([s], a[None])[0] for s, a in zip(scenes, actions, strict=True)]
    assert batched == single


def test_agent_discs_are_drawn_where_each_frame_has_its_agent():
    """Frames sharing an agent's place share one disc; every disc is the pixels whose centres
    lie within the agent's radius."""
    from sim.nav2d import render as R

    rng = np.random.default_rng(0)
    xy = np.round(rng.uniform(-6, 6, size=(40, 2)), 1)
    xy[20:] = xy[:20]  # each place twice
    layers = rng.integers(0, 200, size=(40, 36, 36, 3), dtype=np.uint8)
    got = R.draw_agents(layers, xy)
    centres = (np.arange(36) + 0.5) / R.PX_PER_UNIT - R.ARENA
    for b, (x, y) in enumerate(xy):
        disc = (centres[None, :] - x) ** 2 + (centres[::-1][:, None] - y) ** 2 <= R.AGENT_RADIUS**2
        want = layers[b].copy()
        want[disc] = 255
        np.testing.assert_array_equal(got[b], want)


def test_training_layouts_never_show_one_frame_with_two_expert_actions(nav):
    # the expert crosses at a speed set by where it started: a start on (or near) another
    # start's path to the same goal would give one frame two labels, which the base policy
    # cannot fit. 21 layouts, one demonstration each, goals never bottom-left (`other`'s)
    from sim.nav2d.dynamics import dist
    from sim.nav2d.render import CORNERS
    from sim.nav2d.tasks import GOAL, START, STARTS, TRAIN_LAYOUTS

    assert len(TRAIN_LAYOUTS) == 21 == nav.cloning.demonstrations
    assert {g for _, g in TRAIN_LAYOUTS} == set(CORNERS) - {(-5.0, -5.0)}
    assert {nav.train_task(i).scene.agent[:2] for i in range(21)} == set(STARTS)
    first = TRAIN_LAYOUTS.index((START, GOAL))  # seed 0's, the canonical layout
    for i, (start, goal) in enumerate(TRAIN_LAYOUTS):
        demo = nav.demonstrate(nav.train_task(i - first))
        assert demo.success and demo.scenes[0].agent[:2] == start
        for other, g in TRAIN_LAYOUTS:
            if g == goal and other != start:  # how close this path passes the other start
                assert min(dist(s.agent, other) for s in demo.scenes) >= 1.25 - 1e-9
