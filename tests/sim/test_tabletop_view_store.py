"""Top views kept on disk: a later compositor reads them instead of drawing them, gives the same
frames, and drops a file whose views its renderer does not draw."""

from __future__ import annotations

import numpy as np
import pytest

import sim
from sim.tabletop import tasks as TK
from sim.tabletop import view_store
from sim.tabletop.composite import Compositor
from sim.tabletop.model import Table
from sim.tabletop.world import TabletopWorld
from tests.sim.test_tabletop_composite import _random_scenes


@pytest.fixture(scope="module")
def mujoco_world():
    return TabletopWorld(compositing=False)


def _compositor(mujoco_world, store):
    return Compositor(mujoco_world._parts()[1].render_batch, TK.make_scene(), store=store)


def test_views_are_read_back_instead_of_drawn(mujoco_world, tmp_path):
    store = tmp_path / "views.npz"
    scenes = _random_scenes(sim.get_world("tabletop"), 40, 3, anywhere=False)
    want = mujoco_world.render_batch(scenes)
    first = _compositor(mujoco_world, store)
    assert np.array_equal(first.render_batch(scenes), want) and first.drawn > 4
    assert store.is_file() and len(view_store.load(store)) == len(first.views)
    later = _compositor(mujoco_world, store)
    assert later.drawn <= 4  # only the few drawn again to check the file
    assert np.array_equal(later.render_batch(scenes), want) and later.drawn <= 4
    later.reopen()
    assert len(later.views) == len(first.views) and later.drawn <= 8


def test_a_file_of_other_pixels_is_dropped(mujoco_world, tmp_path):
    store = tmp_path / "views.npz"
    scenes = _random_scenes(sim.get_world("tabletop"), 20, 4, anywhere=False)
    _compositor(mujoco_world, store).render_batch(scenes)
    views = view_store.load(store)
    bad = {
        k: type(v)(v.rows, v.cols, 255 - v.colours, v.top, v.left, v.near) for k, v in views.items()
    }
    view_store.save(store, bad)  # as another GL driver might have drawn them
    again = _compositor(mujoco_world, store)
    assert again.render_batch(scenes).tolist() == mujoco_world.render_batch(scenes).tolist()
    assert again.drawn >= len(views)  # every view drawn anew, none taken from the file


@pytest.mark.parametrize("content", [b"", b"not a zip", b"PK\x03\x04broken"])
def test_an_unreadable_file_is_no_views(tmp_path, content):
    store = tmp_path / "views.npz"
    store.write_bytes(content)
    assert view_store.load(store) == {}
    assert view_store.load(tmp_path / "missing.npz") == {}


def test_the_file_is_named_for_the_model_as_compiled(mujoco_world):
    """The same file in every process: whatever scene the model holds when it is named."""
    table = mujoco_world._parts()[0]
    path = view_store.store_path(table, 80)
    assert path == view_store.store_path(table, 80) != view_store.store_path(table, 64)
    assert path.suffix == ".npz" and path.parent.name == "tabletop-views"
    scene = mujoco_world.test_task("other", 3).scene
    mujoco_world.render_batch([scene])  # the model now holds another scene's looks
    fresh = Table()
    assert view_store.store_path(fresh, 80) == path
    fresh.load(scene)
    assert view_store.store_path(fresh, 80) == path
