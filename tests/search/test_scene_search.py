"""Continuous scene parameters (World.scene_parameters), the surrogate search over them
(search.scene_search) and the diagnosis of what it finds (search.scene_diagnosis).

The search and diagnosis tests use the tabletop (one MuJoCo primitive per rollout) and a
policy planted with a blind spot: it reads the object's and the goal's centres off the frame
and picks and places there, as the expert does, except that a red object right of x = 0.1 m
is picked at its mirror image, where nothing is: it fails there, and only its colour restores
it."""

from __future__ import annotations

import numpy as np
import pytest

from dfa_viz.cli import main
from policy.model import Policy
from search.scene_diagnosis import diagnose
from search.scene_search import Neighbourhoods, SceneSearch, surrogate, uniform
from sim import get_world
from sim.core import Edit, UserError
from sim.core.parameters import InvalidScene
from sim.nav2d import render as R

REGION_X = 0.1  # the planted blind spot: a red object whose centre is right of this
PX_PER_M, HALF_M = 100.0, 0.4  # the tabletop's 80 px frame over [-0.4, 0.4]^2


def _eroded(mask: np.ndarray) -> np.ndarray:
    """bool (H, W): pixels whose 3x3 neighbourhood is all in the mask (drops thin handles)."""
    m = np.pad(mask, 1)
    h, w = mask.shape
    return np.all([m[i : i + h, j : j + w] for i in range(3) for j in range(3)], axis=0)


def _centre(mask: np.ndarray) -> tuple[float, float]:
    rows, cols = np.nonzero(mask)
    return (cols.mean() + 0.5) / PX_PER_M - HALF_M, HALF_M - (rows.mean() + 0.5) / PX_PER_M


class BlindSpotPolicy(Policy):
    """Pick at the object's centre (saturated pixels that are not the goal's blue), place at
    the goal's (blue pixels); a red object right of REGION_X is picked at (-x, y)."""

    def __init__(self) -> None:
        super().__init__(None, discrete=False, obs_shape=(80, 80, 3), action_dim=4)

    def _forward(self, obs: np.ndarray) -> np.ndarray:
        out = np.zeros((len(obs), 4), np.float32)
        for b, frame in enumerate(obs.astype(np.int32)):
            r, g, bl = frame[..., 0], frame[..., 1], frame[..., 2]
            blue = (bl > r + 40) & (bl > g + 20)
            thing = (frame.max(-1) - frame.min(-1) > 40) & ~blue
            if not _eroded(thing).any() or not _eroded(blue).any():
                continue
            ox, oy = _centre(_eroded(thing))
            gx, gy = _centre(_eroded(blue))
            pixels = frame[_eroded(thing)].mean(0)
            red = pixels[0] > pixels[1] + 60 and pixels[0] > pixels[2] + 60
            if red and ox > REGION_X:
                ox = -ox
            out[b] = (ox, oy, gx, gy)
        return out


@pytest.fixture(scope="module")
def tabletop():
    return get_world("tabletop")


SMALL = SceneSearch(budget=30, spread=1.0, start=10, batch=10, pool=100)


def _hoods(world):
    return Neighbourhoods(world, [world.train_task(s) for s in range(4)], SMALL.spread)


def test_parameters_set_read_back_and_refuse_overlaps(tabletop):
    nav = get_world("nav2d")
    task = nav.train_task(0)
    scene = nav.with_parameters(task.scene, (1.5, -2.0, -3.0, 4.0))
    assert nav.parameters_of(scene) == (1.5, -2.0, -3.0, 4.0)
    assert scene.obj("goal").values == task.scene.obj("goal").values
    frame = nav.render(scene)
    col, row = R.to_px(1.5, -2.0)
    assert tuple(frame[int(row), int(col)]) == R.COLOURS["red"]  # the X's centre, drawn there
    assert (
        nav.render(task.scene) == nav.render(nav.with_parameters(task.scene, (5, -5, -5, 5)))
    ).all()
    for bad in ((1.0, 1.0, 1.5, 1.5), (6.0, 0.0, 0.0, 0.0), (0.0, 0.0, 3.0), (np.nan, 0, 3, 3)):
        with pytest.raises(InvalidScene):
            nav.with_parameters(task.scene, bad)
    t = tabletop.train_task(0)
    moved = tabletop.with_parameters(t.scene, (0.1, 0.05, -0.2, -0.1))
    assert tabletop.parameters_of(moved) == (0.1, 0.05, -0.2, -0.1)
    assert moved.obj("object").pos[2:] == t.scene.obj("object").pos[2:]
    with pytest.raises(InvalidScene):
        tabletop.with_parameters(t.scene, (0.0, 0.0, 0.1, 0.1))  # 0.14 m apart: overlapping
    doorkey = get_world("doorkey")
    moved = doorkey.with_parameters(doorkey.train_task(0).scene, (2.4, 7.6, 9.0))
    assert doorkey.parameters_of(moved) == (2.0, 8.0, 9.0)  # projected onto rows
    assert moved.obj("door").pos == (5.0, 8.0)
    with pytest.raises(InvalidScene):
        doorkey.with_parameters(moved, (0.0, 5.0, 5.0))
    grid = get_world("minigrid:MiniGrid-Empty-5x5-v0")
    assert grid.scene_parameters == ()
    with pytest.raises(UserError):
        grid.with_parameters(grid.sample_scene(0), ())


def test_the_surrogate_finds_the_planted_region_and_repeats_itself(tabletop):
    policy = BlindSpotPolicy()
    hoods = _hoods(tabletop)
    found = surrogate(tabletop, policy.act, hoods, SMALL, seed=0)
    assert len(found) == SMALL.budget
    failed = [p for p in found if p.failed]
    assert failed and all(p.values[0] > REGION_X for p in failed)
    inside = [p for p in found if p.values[0] > REGION_X + 0.02 and not p.expert_failed]
    assert all(p.failed for p in inside)  # the region fails wherever the expert succeeds
    assert surrogate(tabletop, policy.act, hoods, SMALL, seed=0) == found
    assert [p.values for p in uniform(tabletop, policy.act, hoods, SMALL, seed=1)] != [
        p.values for p in found
    ]


def test_the_diagnosis_of_a_failure_restores_success(tabletop):
    policy = BlindSpotPolicy()
    hoods = _hoods(tabletop)
    failed = next(p for p in surrogate(tabletop, policy.act, hoods, SMALL, seed=0) if p.failed)
    task = hoods.task(failed.task, failed.values)
    d = diagnose(tabletop, policy, task, max_size=1)
    assert d.size == 1 and d.restores and d.changes is not None
    edit = Edit.from_list(d.changes)
    assert {(c.slot, c.concept) for c in edit.changes} == {("object", "colour")}
    replayed = tabletop.rollout(task, policy.act, scene=tabletop.apply(task.scene, edit))
    assert replayed.success
    assert not tabletop.rollout(task, policy.act).success


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--world", "minigrid:MiniGrid-Empty-5x5-v0"), "no continuous scene parameters"),
        (("--budget", "0"), "--budget"),
        (("--spread", "1.5"), "--spread"),
        (("--diagnose", "-1"), "--diagnose"),
    ],
)
def test_bad_positions_options_are_one_line(capsys, tmp_path, args, message):
    assert main(["experiment", "positions", "--out", str(tmp_path / "o"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dfa: error: ") and message in err[0], err
