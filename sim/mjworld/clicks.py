"""Waypoints of a MuJoCo world's end effector clicked on its frames (demo_input "effector"),
and the rollout that follows them.

A click in the environment's own view (the frame's first square) is a ray from the camera that
drew it, through the clicked pixel (mjv_cameraInModel, mjv_frustumHeight), into the scene
(mj_ray over the geom groups the camera draws): on a slot that moves (the object, a
distractor) it is a grasp of that slot; on anything else (the table, the floor, the robot) a
waypoint ABOVE_M over the point it met. A click in an extra view (Fetch's low view across the
table) on the same point places the waypoint before it where the two rays pass nearest each
other: a target in the air, which the first view alone sees along a line.

Following: the end effector goes to each waypoint in turn with the world's proportional step
(`effector_action`, its expert's); a grasp comes down onto the slot as it lines up under it
(from HOVER_M above), closes the fingers, waits CLOSING_STEPS steps and lifts what it holds
HOVER_M before it goes on; the fingers stay closed from then on. A waypoint is reached within
REACHED_M. After the last one the end effector holds there until the horizon.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim.core import Scene, Task, Trajectory, UserError, Waypoint

ABOVE_M = 0.025  # a waypoint clicked on a surface: this high over it (a held block's half)
HOVER_M = 0.06  # a grasp comes down from this high over the slot
LINED_UP_M = 0.01  # this near over the slot (x, y), the end effector goes all the way down
GRASP_M = 0.012  # this near the slot's centre, the fingers close
CLOSING_STEPS = 5  # steps the fingers take to close on what they grasp
REACHED_M = 0.015  # a waypoint this near is reached


def click_ray(world, scene: Scene, u: float, v: float) -> tuple[int, np.ndarray, np.ndarray]:
    """(view, origin (3,), unit direction (3,)): the ray through the pixel at (u, v) of the
    frame (u right, v down, in [0, 1] over all its views side by side) from the camera that
    drew that view (0: the environment's own, k: the k-th extra view)."""
    import mujoco

    n = 1 + len(world.extra_views)
    u, v = float(np.clip(u, 0.0, 1.0)), float(np.clip(v, 0.0, 1.0))
    k = min(int(u * n), n - 1)
    relx, rely = u * n - k, 1.0 - v  # within the view; y up
    pos, forward, up = np.zeros(3), np.zeros(3), np.zeros(3)
    with world._lock:
        renderer, cams, option = world._renderer()
        _, data = world.physics(world.restore(scene))
        renderer.update_scene(data, camera=cams[k], scene_option=option)
        mujoco.mjv_cameraInModel(pos, forward, up, renderer.scene)
        height = mujoco.mjv_frustumHeight(renderer.scene)  # at unit distance; square views
    right = np.cross(forward, up)
    d = forward + (rely - 0.5) * height * up + (relx - 0.5) * height * right
    return k, pos, d / np.linalg.norm(d)


def waypoint(world, scene: Scene, u: float, v: float, last: Waypoint | None) -> Waypoint | None:
    """The waypoint a click at (u, v) on a frame of `scene` makes (see the module docstring);
    None: the ray met nothing."""
    import mujoco

    view, origin, d = click_ray(world, scene, u, v)
    if view > 0:
        if last is None or last.grasp or not last.ray:
            raise UserError(
                "a click in this view places the waypoint clicked just before it in the first "
                "view: click the point in the first view, then the same point here"
            )
        o1, d1 = np.array(last.ray[:3]), np.array(last.ray[3:])
        meet = nearest_between(o1, d1, origin, d)
        if meet is None:
            return None
        return Waypoint(tuple(round(float(c), 4) for c in meet), ray=last.ray, replaces=True)
    ray = tuple(round(float(c), 6) for c in (*origin, *d))
    with world._lock:
        model, data = world.physics(world.restore(scene))
        groups = np.zeros(mujoco.mjNGROUP, np.uint8)
        groups[list(world.drawn_groups)] = 1
        geom = np.zeros(1, np.int32)
        far = mujoco.mj_ray(model, data, origin, d, groups, 1, -1, geom)
        if far < 0:
            return None
        hit = origin + far * d
        body = int(model.geom_bodyid[geom[0]])
        slot = _slot_of(world, model, body)
    if slot is not None and slot.moves:
        return Waypoint(tuple(round(float(c), 4) for c in scene.obj(slot.name).pos[:3]),
                        grasp=slot.name, on=f"the {slot.name}", ray=ray)  # fmt: skip
    on = f"the {slot.name}" if slot is not None else "the floor" if body == 0 else "the robot"
    return Waypoint((round(float(hit[0]), 4), round(float(hit[1]), 4),
                     round(float(hit[2] + ABOVE_M), 4)), on=on, ray=ray)  # fmt: skip


def nearest_between(o1, d1, o2, d2) -> np.ndarray | None:
    """float (3,): the midpoint of the shortest segment between two rays (o + t d, t >= 0;
    d unit), or None where they are parallel."""
    w = o1 - o2
    b, d, e = float(d1 @ d2), float(d1 @ w), float(d2 @ w)
    den = 1.0 - b * b
    if den < 1e-9:
        return None
    t1, t2 = max(0.0, (b * e - d) / den), max(0.0, (e - b * d) / den)
    return 0.5 * (o1 + t1 * d1 + o2 + t2 * d2)


def _slot_of(world, model, body: int):
    """The SlotSpec whose body is `body` or holds it; None: none does."""
    by_name = {s.body: s for s in world.all_slots() if s.body is not None}
    while body > 0:
        spec = by_name.get(model.body(body).name)
        if spec is not None:
            return spec
        body = int(model.body_parentid[body])
    return None


def follow(world, task: Task, waypoints: Sequence[Waypoint]) -> Trajectory:
    """The end effector led through `waypoints` from the task's scene (see the module
    docstring), judged by R'."""
    if not waypoints:
        raise UserError("click at least one waypoint first")
    scenes, actions = [task.scene], []
    k, closed, waited, to, lift = 0, False, 0, None, None
    for _ in range(world.horizon):
        scene = scenes[-1]
        with world._lock:
            grip = world.grip_pos(world.restore(scene))
        if lift is not None:  # up off where it grasped, before it goes on
            to = lift
            if np.linalg.norm(to - grip) < REACHED_M:
                lift = None
        elif k < len(waypoints):
            w = waypoints[k]
            to = np.array(w.pos, float)
            if w.grasp:
                to = np.array(scene.obj(w.grasp).pos[:3], float)
                off = float(np.linalg.norm((to - grip)[:2]))
                if waited or np.linalg.norm(to - grip) < GRASP_M:
                    closed, waited = True, waited + 1
                    if waited > CLOSING_STEPS:
                        k, waited, lift = k + 1, 0, to + np.array([0.0, 0.0, HOVER_M])
                else:
                    to[2] += min(HOVER_M, 4.0 * max(0.0, off - LINED_UP_M))
            elif np.linalg.norm(to - grip) < REACHED_M:
                k += 1
        a = np.asarray(world.effector_action(grip, to, closed))
        actions.append(a)
        scenes.append(world.step_batch([scene], a[None])[0])
    obs = world.render_batch(scenes)  # (T + 1, H, W, 3)
    return Trajectory(tuple(scenes), obs, np.stack(actions), world.success(task, scenes))
