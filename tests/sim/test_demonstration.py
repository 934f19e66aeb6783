"""A demonstration someone brought is checked and replayed before anything relies on it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim import get_world
from sim.core import Trajectory, UserError, check_demonstration, require_success


@pytest.fixture(scope="module")
def task(nav):
    return nav.test_task("object_ti", 0)


@pytest.fixture(scope="module")
def demo(nav, task):
    return nav.demonstrate(task)


def _with(demo: Trajectory, **fields) -> Trajectory:
    return dataclasses.replace(demo, **fields)


def test_a_good_demonstration_is_replayed_exactly(nav, task, demo):
    back = check_demonstration(nav, task, demo)
    assert back.equals(demo) and back.success


def test_nan_and_inf_actions_are_refused(nav, task, demo):
    for bad in (np.nan, np.inf):
        actions = demo.actions.copy()
        actions[7, 1] = bad
        with pytest.raises(UserError, match="the action at step 7 is not a finite number"):
            check_demonstration(nav, task, _with(demo, actions=actions))


def test_integer_actions_in_a_continuous_world_are_refused(nav, task, demo):
    ints = demo.actions.astype(np.int64)
    with pytest.raises(UserError, match=r"actions of dtype int64.*nav2d needs float actions"):
        check_demonstration(nav, task, _with(demo, actions=ints))
    doorkey = get_world("doorkey")
    dk_task = doorkey.test_task("object_ti", 0)
    dk_demo = doorkey.demonstrate(dk_task)
    floats = dk_demo.actions.astype(np.float32)
    with pytest.raises(UserError, match=r"doorkey needs integer actions in 0..5"):
        check_demonstration(doorkey, dk_task, _with(dk_demo, actions=floats))
    big = dk_demo.actions.copy()
    big[0] = 9
    with pytest.raises(UserError, match=r"doorkey needs integer actions in 0..5"):
        check_demonstration(doorkey, dk_task, _with(dk_demo, actions=big))


def test_frames_of_another_size_are_refused(nav, task, demo):
    small = demo.observations[:, :20, :20]
    with pytest.raises(
        UserError, match=r"frames of shape \(20, 20, 3\).*nav2d renders \(36, 36, 3\)"
    ):
        check_demonstration(nav, task, _with(demo, observations=np.ascontiguousarray(small)))


def test_scenes_of_another_world_are_refused(nav, task, demo):
    other = tuple(
        dataclasses.replace(s, world="tabletop") if i > 3 else s for i, s in enumerate(demo.scenes)
    )
    with pytest.raises(UserError, match="its scenes belong to tabletop, not nav2d"):
        check_demonstration(nav, task, _with(demo, scenes=other))


def test_another_start_is_refused(nav, task, demo):
    with pytest.raises(UserError, match="starts from another scene"):
        check_demonstration(nav, nav.train_task(), demo)


def test_only_the_actions_are_trusted(nav, task, demo):
    """Later scenes and the success flag come from the world, not from the file."""
    frozen = tuple([demo.scenes[0]] * len(demo.scenes))  # a file claiming the agent never moved
    back = check_demonstration(nav, task, _with(demo, scenes=frozen, success=False))
    assert back.equals(demo)


def test_a_demonstration_that_fails_the_task_is_refused(nav, task, demo):
    wrong = check_demonstration(nav, task, _with(demo, actions=-demo.actions))
    assert not wrong.success
    with pytest.raises(UserError, match="does not succeed at what the task asks"):
        require_success(task, wrong)
    require_success(task, demo)
