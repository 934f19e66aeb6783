"""Top views kept on disk: a later compositor reads them instead of drawing them and gives the
same frames; a damaged view, a damaged file, a file of another renderer and two processes
writing at once never put other pixels in a frame (a cache cannot change a diagnosis)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import sim
from policy import base_policy
from policy.train import training_demos
from sim.core import UserError, files
from sim.tabletop import tasks as TK
from sim.tabletop import view_store
from sim.tabletop.composite import PROBE, Compositor
from sim.tabletop.model import Table
from sim.tabletop.top_view import same
from sim.tabletop.world import TabletopWorld
from tests.sim.test_tabletop_composite import _random_scenes

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def mujoco_world():
    return TabletopWorld(compositing=False)


def _compositor(mujoco_world, store, draw=None):
    draw = draw or mujoco_world._parts()[1].render_batch
    return Compositor(draw, TK.make_scene(), store=store)


def _lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("dfa: ")]


def _arrays(store: Path) -> dict[str, np.ndarray]:
    with np.load(store, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _damage(store: Path, hit, change) -> int:
    """Rewrite `store` with `change(colours)` applied to the views whose key `hit` accepts,
    every stored digest kept as it was (as a disk or a hand might damage it); the count hit."""
    z = _arrays(store)
    at = np.concatenate([[0], np.cumsum(z["counts"])])
    hits = 0
    for i, key in enumerate(z["keys"]):
        if hit(i, tuple(str(key).split("\t"))):
            z["colours"][at[i] : at[i + 1]] = change(z["colours"][at[i] : at[i + 1]])
            hits += 1
    np.savez(store, **z)
    return hits


def _stored_views(store: Path, renderer: str) -> dict:
    got = view_store.read(store, renderer=renderer)
    assert got.problem is None, got.problem
    return got.views


def test_views_are_read_back_instead_of_drawn(mujoco_world, tmp_path, capsys):
    store = tmp_path / "views.npz"
    scenes = _random_scenes(sim.get_world("tabletop"), 40, 3, anywhere=False)
    want = mujoco_world.render_batch(scenes)
    first = _compositor(mujoco_world, store)
    assert np.array_equal(first.render_batch(scenes), want) and first.drawn > len(PROBE)
    assert len(_stored_views(store, first.renderer)) == len(first.views)
    later = _compositor(mujoco_world, store)
    assert later.drawn == len(PROBE)  # only the views that name the renderer
    assert np.array_equal(later.render_batch(scenes), want) and later.drawn == len(PROBE)
    later.reopen()
    assert len(later.views) == len(first.views) and later.drawn == 2 * len(PROBE)
    assert _lines(capsys.readouterr().err) == []


def test_damaged_views_are_dropped_and_drawn_again(mujoco_world, tmp_path, capsys):
    """Six later views greyed by hand, their digests kept: not one of them reaches a frame."""
    store = tmp_path / "views.npz"
    scenes = _random_scenes(sim.get_world("tabletop"), 40, 5, anywhere=False)
    want = mujoco_world.render_batch(scenes)
    _compositor(mujoco_world, store).render_batch(scenes)
    n = len(_arrays(store)["keys"])
    greyed = _damage(store, lambda i, k: i >= n - 6, lambda c: np.full_like(c, 128))
    assert greyed == 6 and not set(_arrays(store)["keys"][-6:]) & {"\t".join(k) for k in PROBE}
    capsys.readouterr()
    again = _compositor(mujoco_world, store)
    assert _lines(capsys.readouterr().err) == [
        f"dfa: 6 of {n} cached tabletop views in {store} did not match their digests; "
        "they are drawn again"
    ]
    assert len(again.views) == n - 6
    assert np.array_equal(again.render_batch(scenes), want)
    assert again.drawn == len(PROBE) + 6  # the six drawn anew, none taken from the file
    third = _compositor(mujoco_world, store)  # the file now holds the six drawn again
    assert np.array_equal(third.render_batch(scenes), want) and third.drawn == len(PROBE)
    assert _lines(capsys.readouterr().err) == []


def test_broadly_damaged_views_never_reach_the_base_policy(mujoco_world, tmp_path, monkeypatch):
    """Every view inverted, digests kept: the next run says so in one line, draws them again,
    and the committed tabletop policy loads from the training frames MuJoCo draws."""
    monkeypatch.setenv("DFA_CACHE", str(tmp_path))
    training_demos(TabletopWorld())  # the views of the training frames, kept on disk
    (store,) = (tmp_path / "tabletop-views").glob("*.npz")
    n = len(_arrays(store)["keys"])
    assert _damage(store, lambda i, k: True, lambda c: 255 - c) == n
    run = subprocess.run(
        [sys.executable, "-c", _NEXT_RUN], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    assert _lines(run.stderr) == [
        f"dfa: {n} of {n} cached tabletop views in {store} did not match their digests; "
        "they are drawn again"
    ], run.stderr
    assert run.stdout.splitlines()[-1] == "training frames are MuJoCo's: True", run.stdout


_NEXT_RUN = """
import numpy as np, sim
from policy import base_policy
from policy.train import training_demos
from sim.tabletop.world import TabletopWorld

world = sim.get_world("tabletop")
base_policy(world)  # the recipe check: the training frames' colours as committed
mujoco = TabletopWorld(compositing=False)
same = all(
    np.array_equal(d.observations, mujoco.render_batch(list(d.scenes)))
    for d in training_demos(world)
)
print("training frames are MuJoCo's:", same)
"""


def test_a_wrong_cache_that_passes_its_digests_is_named_before_a_retrain(
    mujoco_world, tmp_path, monkeypatch
):
    """Views inverted and their digests written anew (nothing on disk can tell): the recipe
    check refuses in one line that names the cache and how to clear it before a retrain, and
    clearing it as told is enough."""
    monkeypatch.setenv("DFA_CACHE", str(tmp_path / "cache"))
    training_demos(TabletopWorld())
    (store,) = files.cache_dir().glob("tabletop-views/*.npz")
    renderer = _compositor(mujoco_world, store).renderer
    inverted = {
        k: type(v)(v.rows, v.cols, 255 - v.colours, v.top, v.left, v.near)
        for k, v in _stored_views(store, renderer).items()
    }
    view_store.save(store, inverted, renderer=renderer)
    with pytest.raises(UserError) as err:
        base_policy(TabletopWorld())
    message = str(err.value)
    assert "\n" not in message and "the training frames look different" in message
    cache = f"delete the cache {files.cache_dir()} ($DFA_CACHE, else ~/.cache/dfa) and run again"
    assert cache in message and message.index(cache) < message.index("dfa train --retrain")
    shutil.rmtree(files.cache_dir())
    base_policy(TabletopWorld())


def test_a_file_another_renderer_drew_is_dropped_whole(mujoco_world, tmp_path, capsys):
    """Another GL driver (here MuJoCo's pixels with the lowest bit of blue flipped) takes no
    view from a file MuJoCo's renderer wrote, and the file it writes holds only its own."""
    store = tmp_path / "views.npz"
    scenes = _random_scenes(sim.get_world("tabletop"), 20, 4, anywhere=False)
    mine = _compositor(mujoco_world, store)
    mine.render_batch(scenes)
    n = len(_arrays(store)["keys"])
    draw = mujoco_world._parts()[1].render_batch

    def other(scenes):
        out = draw(scenes)
        out[..., 2] ^= 1
        return out

    capsys.readouterr()
    theirs = _compositor(mujoco_world, store, other)
    assert _lines(capsys.readouterr().err) == [
        f"dfa: {n} of {n} cached tabletop views in {store} were drawn by another renderer; "
        "they are drawn again"
    ]
    assert np.array_equal(theirs.render_batch(scenes), other(scenes))
    assert theirs.drawn >= n  # every view drawn anew, none taken from the file
    assert view_store.read(store, renderer=theirs.renderer).problem is None
    assert view_store.read(store, renderer=mine.renderer).views == {}  # never a mixed file


def _old_format(tmp_path: Path) -> bytes:
    """A store file as written before views carried digests."""
    z = _arrays(tmp_path / "views.npz")
    old = tmp_path / "old.npz"
    np.savez(old, **{k: v for k, v in z.items() if k not in ("digests", "renderer")})
    return old.read_bytes()


@pytest.mark.parametrize(
    ("content", "why"),
    [
        (b"", "could not be read"),
        (b"not a zip", "could not be read"),
        (b"PK\x03\x04broken", "could not be read"),
        (_old_format, "carry no digests (an older format)"),
    ],
)
def test_an_unreadable_file_is_no_views_and_one_line(mujoco_world, tmp_path, capsys, content, why):
    store = tmp_path / "views.npz"
    scenes = _random_scenes(sim.get_world("tabletop"), 8, 6, anywhere=False)
    if callable(content):
        _compositor(mujoco_world, store).render_batch(scenes)
        content = content(tmp_path)
    store.write_bytes(content)
    capsys.readouterr()
    again = _compositor(mujoco_world, store)
    (line,) = _lines(capsys.readouterr().err)
    assert line.startswith("dfa: ") and line.endswith(
        f"cached tabletop views in {store} {why}; they are drawn again"
    )
    assert np.array_equal(again.render_batch(scenes), mujoco_world.render_batch(scenes))
    assert view_store.read(store, renderer=again.renderer).problem is None  # written anew
    assert view_store.read(tmp_path / "missing.npz", renderer=again.renderer) == (
        view_store.Stored()
    )


def _draw_into_store(seeds: tuple[int, ...], ready: str, go: str) -> None:
    """One process of the two below: the views of its scenes drawn into the shared store (the
    world's own, under $DFA_CACHE), a few scenes at a time, once both processes are ready."""
    world = sim.get_world("tabletop")
    scenes = [s for seed in seeds for s in _random_scenes(world, 24, seed, anywhere=False)]
    world.render_batch(scenes[:0])  # MuJoCo up before the start
    Path(ready).touch()
    while not Path(go).exists():
        time.sleep(0.01)
    for i in range(0, len(scenes), 4):
        world.render_batch(scenes[i : i + 4])


def test_two_processes_sharing_a_store_lose_nothing_and_mix_nothing(
    mujoco_world, tmp_path, monkeypatch, capsys
):
    monkeypatch.setenv("DFA_CACHE", str(tmp_path))
    world = sim.get_world("tabletop")
    jobs = {(11, 12): None, (12, 13): None}  # different views, and the same ones (seed 12)
    for k, seeds in enumerate(jobs):
        code = (
            "from tests.sim.test_tabletop_view_store import _draw_into_store; "
            f"_draw_into_store({seeds}, {str(tmp_path / f'ready{k}')!r}, {str(tmp_path / 'go')!r})"
        )
        jobs[seeds] = subprocess.Popen(
            [sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
    while not all((tmp_path / f"ready{k}").exists() for k in range(len(jobs))):
        assert all(p.poll() is None for p in jobs.values()), "a process ended before the start"
        time.sleep(0.05)
    (tmp_path / "go").touch()
    for p in jobs.values():
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0 and b"Traceback" not in err and b"dfa:" not in err, err.decode()

    scenes = [
        s
        for seeds in jobs
        for seed in seeds
        for s in _random_scenes(world, 24, seed, anywhere=False)
    ]
    (store,) = (tmp_path / "tabletop-views").glob("*.npz")
    assert store == view_store.store_path(Table(), 80)
    assert sorted(p.name for p in store.parent.iterdir()) == [store.name, store.name + ".lock"]
    reader = _compositor(mujoco_world, store)  # the third process
    assert _lines(capsys.readouterr().err) == []
    kept = _stored_views(store, reader.renderer)
    want = {(o.value("shape"), o.value("colour")) for s in scenes for o in s.objects if o.present}
    assert set(kept) == want | set(PROBE)  # every view either process drew: none lost
    fresh = Compositor(mujoco_world._parts()[1].render_batch, TK.make_scene()).top_views(list(kept))
    assert all(same(kept[k], fresh[k]) for k in kept)
    assert np.array_equal(reader.render_batch(scenes), mujoco_world.render_batch(scenes))
    assert reader.drawn == len(PROBE)


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
