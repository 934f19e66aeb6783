import itertools

import numpy as np
import pytest

from sim import PAPER_WORLDS
from sim.core import ABSENT, PRESENCE, PRESENT, Change, Edit, Scene, Trajectory, UserError


def test_phi_encode_decode_round_trips_every_single_edit(nav):
    task = nav.test_task("distractor_ti", 0)
    for edit in [
        Edit.of(c)
        for cs in __import__("sim.core", fromlist=["x"]).single_changes(nav.space, task.scene)
        for c in cs
    ]:
        scene = nav.apply(task.scene, edit)
        phi = nav.space.encode(scene)
        assert phi.shape == (nav.space.dim,) and phi.dtype == np.uint8
        assert nav.space.decode(phi, scene) == scene
        # one-hot per concept of each present slot, zeros for absent ones
        assert phi.sum() == 2 * sum(o.present for o in scene.objects)


def test_apply_checks_old_values_and_names(nav):
    scene = nav.train_task().scene
    with pytest.raises(UserError, match="unknown slot 'wall'"):
        nav.apply(scene, Edit.of(Change("wall", "colour", "red", "blue")))
    with pytest.raises(UserError, match="unknown colour 'mauve'"):
        nav.apply(scene, Edit.of(Change("goal", "colour", "red", "mauve")))
    with pytest.raises(UserError, match="unknown concept 'size'"):
        nav.apply(scene, Edit.of(Change("goal", "size", "big", "small")))
    with pytest.raises(UserError, match="is 'red'"):
        nav.apply(scene, Edit.of(Change("goal", "colour", "blue", "green")))
    added = nav.apply(scene, Edit.of(Change("distractor", PRESENCE, ABSENT, PRESENT)))
    assert added.obj("distractor").present and not scene.obj("distractor").present


@pytest.mark.parametrize("name", PAPER_WORLDS)
def test_apply_many_gives_what_apply_gives_and_shares_the_unchanged_objects(name):
    from search import combinations
    from sim import get_world

    world = get_world(name)
    scene = world.test_task("distractor_ti", 1).scene
    edits = [
        e for k in (1, 2, 3) for e in itertools.islice(combinations(world.space, scene, k), 400)
    ]
    got = world.apply_batch(scene, edits)
    assert got == [world.apply(scene, e) for e in edits]
    for edit, after in zip(edits, got, strict=True):
        changed = {c.slot for c in edit.changes}
        assert all(o is scene.obj(o.slot) for o in after.objects if o.slot not in changed)
    bad = Edit.of(Change("goal", "colour", "no such colour", "red"))
    with pytest.raises(UserError):
        world.apply(scene, bad)
    with pytest.raises(UserError):
        world.apply_batch(scene, [*edits[:3], bad])


def test_scene_json_round_trip_is_exact(nav):
    scene = nav.test_task("distractor_tr", 3).scene
    assert Scene.from_dict(scene.to_dict()) == scene
    with pytest.raises(UserError, match="malformed scene"):
        Scene.from_dict({"world": "nav2d"})


def test_trajectory_npz_round_trip_is_bit_exact(nav, tmp_path):
    demo = nav.demonstrate(nav.test_task("object_ti", 1))
    path = demo.save(tmp_path / "demo.npz")
    back = Trajectory.load(path)
    assert back.equals(demo)
    assert back.actions.dtype == demo.actions.dtype == np.float32


def test_malformed_trajectory_files_say_what_is_wrong(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(UserError, match=r"bad.npz: not an .npz archive"):
        Trajectory.load(bad)
    npy = tmp_path / "renamed.npz"
    with open(npy, "wb") as f:
        np.save(f, np.zeros((3, 2)))  # a .npy file given an .npz name
    with pytest.raises(UserError, match=r"renamed.npz: not an .npz archive"):
        Trajectory.load(npy)
    partial = tmp_path / "partial.npz"
    np.savez(partial, actions=np.zeros((3, 2)))
    with pytest.raises(UserError, match="missing"):
        Trajectory.load(partial)
