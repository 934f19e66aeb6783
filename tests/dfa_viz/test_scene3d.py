"""The recording's 3D scene (dfa_viz.scene3d) and the page's meshes (dfa_viz.app.canvas) for
both kinds of View3D: a closed-loop MuJoCo world (FetchPickAndPlace: a pose per step, the
gripper's motion as the action) and the tabletop (its pick-and-place played out on `sim_time`),
each written to an .rrd and read back."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import rrd_read

import sim
from dfa_viz import scene3d
from dfa_viz.app.canvas import SIZE, placed_meshes
from dfa_viz.rrd import RrdFile, recording_id

PICK = "fetch:FetchPickAndPlace-v4"


@pytest.fixture(scope="module")
def fetch():
    world = sim.get_world(PICK)
    demo = world.demonstrate(world.train_task(0))
    assert demo.success
    return world, demo


def _record(tmp_path, world, name, traj) -> dict[str, list[dict]]:
    """scene3d.log_rollout into an .rrd, read back: entity -> its chunks as columns."""
    path = tmp_path / "scene3d.rrd"
    rrd = RrdFile(path, recording_id(world.name, "test", 0))
    scene3d.log_rollout(rrd.rec, world, name, traj)
    rrd.close()
    return rrd_read.chunks(path)


def _by_step(chunks: list[dict], name: str) -> dict[int, list]:
    return {s: v[0] for c in chunks if "step" in c for s, v in zip(c["step"], c[name], strict=True)}


def test_a_fetch_rollout_holds_a_pose_per_step(tmp_path, fetch):
    world, demo = fetch
    chunks = _record(tmp_path, world, "demonstration", demo)
    base = "/scene3d/demonstration"
    assert f"{base}/table" in chunks and f"{base}/view" not in chunks  # the table: a slot
    assert not rrd_read.column(chunks[f"{base}/table"], "Boxes3D:half_sizes")
    steps = list(range(demo.horizon + 1))
    view = world.view3d
    for slot in ("object", "target", "table", "gripper/0", "gripper/1", "gripper/2"):
        rows = chunks[f"{base}/{slot}"]
        mesh = rrd_read.column(rows, "Mesh3D:vertex_positions")
        assert len(mesh) == 1 and len(mesh[0]) >= 36, slot  # logged once, static
        assert not [c for c in rows if "sim_time" in c], slot  # closed loop: steps only
        at = _by_step(rows, "Transform3D:translation")
        assert sorted(at) == steps, slot
        for t in (0, 25, demo.horizon):
            (pose,) = [p for p in view.poses(demo.scenes[t]) if p.slot == slot]
            assert np.allclose(at[t], pose.pos, atol=1e-5), (slot, t)
    # the object goes up with the gripper and ends on the goal
    at = _by_step(chunks[f"{base}/object"], "Transform3D:translation")
    assert max(v[2] for v in at.values()) > at[0][2] + 0.05
    assert np.linalg.norm(np.subtract(at[demo.horizon], world.goal_of(demo.scenes[-1]))) < 0.05
    # an arrow per action: the gripper's motion over its step
    arrows = chunks[f"{base}/action"]
    origins = _by_step(arrows, "Arrows3D:origins")
    vectors = _by_step(arrows, "Arrows3D:vectors")
    assert sorted(origins) == steps[:-1]
    grip = _by_step(chunks[f"{base}/gripper/0"], "Transform3D:translation")
    for t in steps[:-1]:
        origin, _ = view.arrow(demo.scenes[t], demo.actions[t], demo.scenes[t + 1])
        assert np.allclose(origins[t], origin, atol=1e-5)
        if t + 1 < demo.horizon:  # each arrow ends where the next begins
            assert np.allclose(np.add(origins[t], vectors[t]), origins[t + 1], atol=1e-5)
        # the gripper link moves with the grip point (Fetch holds the gripper's orientation)
        moved = np.subtract(grip[t + 1], grip[t])
        assert np.linalg.norm(moved - np.asarray(vectors[t])) < 0.003, t


def test_a_tabletop_rollout_plays_its_pick_and_place_out(tmp_path):
    world = sim.get_world("tabletop")
    demo = world.demonstrate(world.train_task(0))
    chunks = _record(tmp_path, world, "demonstration", demo)
    base = "/scene3d/demonstration"
    assert rrd_read.column(chunks[f"{base}/table"], "Boxes3D:half_sizes")
    assert rrd_read.column(chunks[f"{base}/view"], "LineStrips3D:strips")
    rows = chunks[f"{base}/object"]
    assert sorted(_by_step(rows, "Transform3D:translation")) == [0, 1]
    times = rrd_read.column([c for c in rows if "sim_time" in c], "sim_time")
    assert len(times) >= 10 and times == sorted(times)
    (origin,) = rrd_read.column(chunks[f"{base}/action"], "Arrows3D:origins")
    a = np.asarray(demo.actions[0], float)
    assert np.allclose(origin[0], (a[0], a[1], 0.15), atol=1e-6)  # above the pick point
    assert chunks[f"{base}/trail/object"]


def test_the_page_places_the_meshes_around_the_views_centre(fetch):
    world, demo = fetch
    view = world.view3d
    k = SIZE / (2 * view.view_half_m)
    placed = {m.path: m for m in placed_meshes(view, demo, None, 10)}
    poses = {p.slot: p for p in view.poses(demo.scenes[10])}
    assert set(placed) == {f"/scenes/failed/{slot}" for slot in poses}
    for slot, p in poses.items():
        m = placed[f"/scenes/failed/{slot}"]
        assert np.allclose(m.position, (np.subtract(p.pos, view.centre_m) * k) + (0, 0, 0.01))
        assert m.wxyz == p.quat and not m.wireframe
        assert np.allclose(m.vertices, np.asarray(view.mesh(p.shape).vertices) * k, atol=1e-4)
    # the table top at the plane, within the plane's square
    table = placed["/scenes/failed/table"]
    top = table.position[2] + table.vertices[:, 2].max()
    assert abs(top - 0.01) < 1e-4 and np.abs(table.position[:2]).max() < SIZE / 2
    # a counterfactual that differs only in the table's colour (the demonstration's actions
    # replayed): the table alone, as a ghost
    task = world.train_task(0)
    table = task.scene.obj("table").with_value("colour", "green")
    cf = world.replay(replace(task, scene=task.scene.with_obj(table)), demo.actions)
    ghosts = [m for m in placed_meshes(view, demo, cf, 10) if m.wireframe]
    assert [m.path for m in ghosts] == ["/scenes/counterfactual/table"]
