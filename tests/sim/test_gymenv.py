"""A plain gymnasium environment as a world through sim.gymenv: docs/examples/grid_reacher.py's
environment and its table of concept edits. The world's frames and steps are the
environment's own; edits change the state the environment is restored to; badly described
environments are one line (`dfa run` in it: tests/dfa_viz/test_world_runs.py)."""

from __future__ import annotations

from pathlib import Path

import gymnasium
import numpy as np
import pytest

import sim
from sim.core import Change, Edit, UserError
from sim.gymenv import ConceptEdit, GymWorld

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"


@pytest.fixture(scope="module")
def reacher():
    import sys

    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    return sim.get_world("grid_reacher:reacher")


def test_frames_and_steps_are_the_environments_own(reacher):
    """Restoring a scene and stepping the world gives what stepping the environment gave."""
    env = gymnasium.make("dfa_examples/GridReacher-v0")
    rng = np.random.default_rng(0)
    for seed in (0, 5, 1_000_003):
        obs, _ = env.reset(seed=seed)
        scene = reacher.layout_scene(seed)
        assert np.array_equal(obs, reacher.render(scene))
        for _ in range(reacher.horizon):
            a = int(rng.integers(reacher.action_dim))
            obs, reward, terminated, truncated, _ = env.step(a)
            scene = reacher.step_batch([scene], np.array([a]))[0]
            assert np.array_equal(obs, reacher.render(scene))
            assert reacher.done(scene) == (terminated or truncated)
            if terminated or truncated:
                assert reacher.meets_reward(reacher.task_for(scene), [scene]) == (reward > 0)
                break


def test_an_edit_changes_the_state_the_environment_is_restored_to(reacher):
    scene = reacher.train_task(0).scene
    green = reacher.apply(scene, Edit.of(Change("target", "colour", "red", "green")))
    x, y = (int(v) for v in reacher.state_of(green)[2:4])  # the target's cell
    cell = reacher.render(green)[y * 4 : (y + 1) * 4, x * 4 : (x + 1) * 4]
    assert (cell == (0, 255, 0)).all()
    assert (reacher.render(scene)[y * 4 : (y + 1) * 4, x * 4 : (x + 1) * 4] == (255, 0, 0)).all()
    shown = reacher.apply(scene, Edit.of(Change("marker", "presence", "absent", "present")))
    assert reacher.state_of(shown)[5] == 1 and reacher.state_of(scene)[5] == 0
    assert np.count_nonzero(reacher.render(shown) != reacher.render(scene)) > 0
    assert reacher.shifts == ("object_ti", "distractor_ti")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(env_id="CartPole-v1"), "a world needs uint8 \\(H, W, 3\\)"),
        (dict(env_id="NoSuchEnv-v0"), "gymnasium cannot make 'NoSuchEnv-v0'"),
        (dict(concepts=(ConceptEdit("colour", ("red",), None),)), "must be 'slot.concept'"),
        (
            dict(concepts=(ConceptEdit("box.presence", ("absent", "present"), None),)),
            "the optional slot 'box' needs a look concept too",
        ),
        (
            dict(concepts=(ConceptEdit("box.presence", ("absent", "gone"), None),)),
            "box.presence takes the values 'present' and 'absent'",
        ),
    ],
)
def test_a_badly_described_environment_is_one_line(reacher, change, message):
    kwargs = dict(
        env_id="dfa_examples/GridReacher-v0",
        get_state=lambda env: env.state,
        set_state=lambda env, s: None,
        concepts=(ConceptEdit("target.colour", ("red", "green"), lambda s, v: s),),
        expert=lambda state: 0,
    )
    with pytest.raises(UserError, match=message) as err:
        GymWorld("bad", **(kwargs | change))
    assert "\n" not in str(err.value)
