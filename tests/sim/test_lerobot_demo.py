"""An episode of a LeRobotDataset as a demonstration (`--demo lerobot:DIR[:episode=N]`): its
actions replayed in the world, its frames checked against the replay's, the first step that
differs named in one line."""

from __future__ import annotations

import numpy as np
import pytest

from sim.core import UserError
from sim.lerobot import Episode, write_dataset
from sim.lerobot.demo import DemoSpec, demonstration, is_spec, parse


@pytest.fixture(scope="module")
def task(nav):
    return nav.test_task("object_ti", 0)


@pytest.fixture(scope="module")
def demo(nav, task):
    return nav.demonstrate(task)


def _write(root, episodes, *, video=False):
    write_dataset(root, episodes, fps=10, robot_type="nav2d", video=video)
    return root


def _episode(traj, task, *, actions=None, frames=None) -> Episode:
    """An episode as another tool writes one: frames and actions, no dfa.* columns."""
    t = traj.horizon
    return Episode(
        task.reward.instruction,
        traj.observations[:t] if frames is None else frames,
        traj.actions if actions is None else actions,
        bool(traj.success),
    )


def test_the_spec_is_parsed_and_its_mistakes_named():
    assert is_spec("lerobot:data/ds") and not is_spec("demo.npz")
    assert parse("lerobot:data/ds") == DemoSpec(root=__import__("pathlib").Path("data/ds"))
    spec = parse("lerobot:/x/ds:episode=12:camera=main")
    assert (str(spec.root), spec.episode, spec.camera) == ("/x/ds", 12, "main")
    for bad in ("lerobot:/x/ds:episode=-1", "lerobot:/x/ds:ep=2", "lerobot:"):
        with pytest.raises(UserError, match=r"lerobot:DIR\[:episode=N\]") as e:
            parse(bad)
        assert "\n" not in str(e.value)


def test_an_episode_that_demonstrates_the_task_is_replayed(tmp_path, nav, task, demo):
    other = nav.replay(task, np.zeros_like(demo.actions))
    root = _write(tmp_path / "ds", [_episode(other, task), _episode(demo, task)])
    back = demonstration(nav, task, DemoSpec(root, 1))
    assert back.equals(demo) and back.success
    # the idle episode is a fine demonstration of itself too (success is judged elsewhere)
    assert not demonstration(nav, task, DemoSpec(root, 0)).success


def test_changed_actions_are_named_at_the_first_frame_they_change(tmp_path, nav, task, demo):
    actions = demo.actions.copy()
    actions[6] += np.float32(0.6)  # step 6 goes elsewhere: frame 7 is not the recorded one
    root = _write(tmp_path / "ds", [_episode(demo, task, actions=actions)])
    with pytest.raises(UserError) as e:
        demonstration(nav, task, DemoSpec(root, 0))
    message = str(e.value)
    assert "\n" not in message
    assert message.startswith(f"{root} episode 0: frame 7 is not what nav2d shows")
    assert "after actions 0 to 6 replayed from the start" in message


def test_an_episode_of_another_task_differs_at_its_first_frame(tmp_path, nav, task):
    elsewhere = nav.test_task("object_ti", 1)
    assert elsewhere.scene != task.scene
    root = _write(tmp_path / "ds", [_episode(nav.demonstrate(elsewhere), elsewhere)])
    with pytest.raises(UserError, match="frame 0 is not what nav2d shows after the task's start"):
        demonstration(nav, task, DemoSpec(root, 0))


def test_frames_of_another_size_and_wrong_actions_are_refused(tmp_path, nav, task, demo):
    small = demo.observations[:-1, :32, :32]
    root = _write(tmp_path / "small", [_episode(demo, task, frames=np.ascontiguousarray(small))])
    with pytest.raises(UserError, match=r"frames of shape \(32, 32, 3\), but nav2d renders"):
        demonstration(nav, task, DemoSpec(root, 0))
    short = _write(tmp_path / "short", [_episode(demo, task, actions=demo.actions)])
    with pytest.raises(UserError, match="no episode 1; it has episodes 0 to 0"):
        demonstration(nav, task, DemoSpec(short, 1))
    three = Episode(task.reward.instruction, demo.observations[:20], demo.actions[:, :1], True)
    root = _write(tmp_path / "one-d", [three])
    with pytest.raises(UserError, match=r"shape \(20, 1\); nav2d needs float actions"):
        demonstration(nav, task, DemoSpec(root, 0))


def test_a_video_episode_is_checked_within_the_codecs_error(tmp_path, nav, task, demo):
    root = _write(tmp_path / "ds", [_episode(demo, task)], video=True)
    assert demonstration(nav, task, DemoSpec(root, 0)).equals(demo)
    actions = demo.actions.copy()
    actions[3:] = 0  # the agent stops at step 3: later frames lose it from where it went
    root = _write(tmp_path / "changed", [_episode(demo, task, actions=actions)], video=True)
    with pytest.raises(UserError, match=r"frame 4 is not what nav2d shows .*video allows"):
        demonstration(nav, task, DemoSpec(root, 0))
