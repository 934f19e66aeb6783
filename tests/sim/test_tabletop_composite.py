"""Tabletop frames composited from cached top views are MuJoCo's own frames, and the search
finds the same counterfactuals with either renderer.

The bound: none. Over every random scene below, the maximum and the mean absolute difference
per channel between the composited frame and MuJoCo's are 0 (both with MuJoCo's 4x MSAA, the
same for both: an anti-aliased edge is a view's mix with the table, which the table frame
reproduces; objects whose edges could mix are drawn together by MuJoCo, as a group).
"""

from __future__ import annotations

import numpy as np
import pytest

import sim
from policy import base_policy, failing_test_task
from search import SearchConfig, counterfactual_search
from sim.core import Obj, Scene
from sim.tabletop import tasks as TK
from sim.tabletop.catalogue import SHAPES
from sim.tabletop.composite import Compositor
from sim.tabletop.world import TabletopWorld

SLOTS = ("object", "goal", "distractor0", "distractor1")


@pytest.fixture(scope="module")
def world():
    return sim.get_world("tabletop")


@pytest.fixture(scope="module")
def mujoco_world():
    return TabletopWorld(compositing=False)


def _random_scenes(world, n: int, seed: int, *, anywhere: bool) -> list[Scene]:
    """n scenes of random looks and presence: objects at distinct area centres, or (anywhere)
    at random whole-centimetre points of the view, which may overlap."""
    rng = np.random.default_rng(seed)
    areas = list(TK.AREAS)
    out = []
    for _ in range(n):
        order = rng.permutation(len(areas))
        objs = []
        for j, slot in enumerate(SLOTS):
            if anywhere:
                xy = tuple(int(v) / 100 for v in rng.integers(-38, 39, size=2))
            else:
                xy = TK.AREAS[areas[order[j]]]
            look = (
                ("shape", SHAPES[rng.integers(len(SHAPES))]),
                ("colour", world.colours[rng.integers(len(world.colours))]),
            )
            objs.append(Obj(slot, j < 2 or bool(rng.random() < 0.6), look, TK.pose(xy)))
        out.append(Scene(TK.WORLD, tuple(objs), (0.0,)))
    return out


def _differences(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Max and mean absolute difference per channel, each float (3,)."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))  # (B, H, W, 3)
    return d.max(axis=(0, 1, 2)).astype(float), d.mean(axis=(0, 1, 2))


def test_composited_frames_equal_mujoco_frames(world, mujoco_world):
    scenes = _random_scenes(world, 200, 0, anywhere=False)
    scenes += _random_scenes(world, 100, 1, anywhere=True)
    # settled scenes after a pick-and-place (the object on the goal: drawn by MuJoCo)
    tasks = [world.test_task(s, 0) for s in ("object_ti", "distractor_tr", "other")]
    starts = [t.scene for t in tasks]
    scenes += world.step_batch(starts, np.stack([world.expert_action(t, t.scene) for t in tasks]))
    world.render_batch(scenes[:1])
    comp = world._compositor
    before = comp.fell_back
    got = world.render_batch(scenes)  # (B, 80, 80, 3)
    want = mujoco_world.render_batch(scenes)
    assert got.shape == want.shape == (len(scenes), 80, 80, 3) and got.dtype == np.uint8
    high, mean = _differences(got, want)
    assert high.tolist() == [0, 0, 0] and mean.tolist() == [0, 0, 0], (high, mean)
    drawn_whole = comp.fell_back - before
    # the area scenes never overlap: all composited; the settled ones are MuJoCo's
    assert 3 <= drawn_whole <= 3 + 100, drawn_whole
    # the same pixels a second time, from the cache
    assert np.array_equal(world.render_batch(scenes[:50]), want[:50])


def test_cache_is_bounded_in_bytes_and_stays_exact(world, mujoco_world):
    camera = mujoco_world._parts()[1]
    small = Compositor(camera.render_batch, TK.make_scene(), cache_bytes=20_000)
    scenes = _random_scenes(world, 60, 2, anywhere=False)
    assert np.array_equal(small.render_batch(scenes), mujoco_world.render_batch(scenes))
    assert small.bytes <= 20_000 and 0 < len(small.views) < small.drawn
    assert small.bytes == sum(v.nbytes for v in small.views.values())


def test_compositing_world_is_the_default(world):
    assert world.compositing and not TabletopWorld(compositing=False).compositing


PLANTED = [("object_ti", 0), ("object_tr", 1), ("distractor_ti", 0), ("distractor_tr", 2)]


@pytest.mark.slow
@pytest.mark.parametrize(("shift", "seed"), PLANTED)
def test_search_finds_the_same_counterfactuals_with_either_renderer(
    world, mujoco_world, shift, seed
):
    policy = base_policy(world)
    task, _ = failing_test_task(world, policy, shift, seed)
    demo = world.demonstrate(task)
    config = SearchConfig.for_world(world)
    got = counterfactual_search(world, policy, task.scene, demo, config=config)
    want = counterfactual_search(mujoco_world, policy, task.scene, demo, config=config)
    assert got.found, (shift, seed, got.summary())
    _same_search(got, want)


def _same_search(got, want) -> None:
    assert [c.edit for c in got.counterfactuals] == [c.edit for c in want.counterfactuals]
    assert [c.edit for c in got.tried] == [c.edit for c in want.tried]
    for a, b in zip(got.tried, want.tried, strict=True):
        assert np.array_equal(a.distances, b.distances, equal_nan=True), a.edit


def test_a_view_reaching_its_quadrants_edge_is_not_cut_from_a_shared_frame(world):
    """A view is cut from a frame of four only when it stays inside its quadrant; an object
    across the quadrants' edges (here: at the centre) is not taken for the top-left's."""
    world.render_batch([world.train_task().scene])
    comp = world._compositor
    centre = comp._studio([("pan", "blue")], ("centre",))
    corner = comp._studio([("pan", "blue")], ("top-left",))
    across, inside = comp.draw([centre, corner])  # (80, 80, 3) each
    assert comp._cut(across, "top-left", whole=False) is None
    assert comp._cut(inside, "top-left", whole=False) is not None
    assert comp._cut(across, "centre", whole=True) is not None


def test_touching_objects_are_pasted_as_groups_each_drawn_once(world, mujoco_world):
    """Every edit up to size 2 of an `other` task: the scenes whose objects touch (a distractor
    added where the object stands) are MuJoCo's frames, with each group drawn once."""
    from search import combinations

    policy = base_policy(world)
    task, _ = failing_test_task(world, policy, "other", 0)
    edits = [e for k in (1, 2) for e in combinations(world.space, task.scene, k)]
    scenes = world.apply_batch(task.scene, edits)
    comp = Compositor(mujoco_world._parts()[1].render_batch, TK.make_scene())
    got = np.concatenate(
        [comp.render_batch(scenes[i : i + 1024]) for i in range(0, len(scenes), 1024)]
    )
    memo: dict = {}
    placed = [comp._placement(s, memo) for s in scenes]
    views = comp.top_views([ko[0] for objs in placed for ko in objs if ko is not None])
    touching = [i for i, objs in enumerate(placed) if comp._clash(objs, views)]
    assert len(touching) >= 100 and comp.fell_back == 0
    groups = {
        tuple(placed[i][k] for k in g) for i in touching for g in comp._touching(placed[i], views)
    }
    assert comp.groups_drawn == len(groups) < len(touching)
    want = mujoco_world.render_batch([scenes[i] for i in touching])
    assert np.array_equal(got[touching], want)
    sample = [i for i in range(0, len(scenes), 97) if i not in set(touching)]
    assert np.array_equal(got[sample], mujoco_world.render_batch([scenes[i] for i in sample]))
