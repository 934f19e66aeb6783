"""The striking demonstrator of FetchSlide: it pushes the puck off towards the goal and lets it
slide, choosing each strike with the environment's own physics.

The puck's slide on FetchSlide's table does not follow a simple friction law (measured: from
1.0 m/s it slows at about 1 m/s^2, then creeps on at a few cm/s), and the gripper's flat
fingers send it along their face's normal rather than towards the goal. So the demonstrator
predicts instead of modelling: from the scene, it steps the world itself (the same steps a
rollout takes) to see where the puck is at the last step if the gripper keeps still now
(`reach`), or strikes once more with a given force and turn and then keeps still; it strikes
with the force whose slide ends nearest the goal (bisection), turned so that the puck heads for
it (a few secant steps on its heading just after the strike), and keeps still while the puck
slides. A strike that falls short is followed by another while the gripper is still behind the
puck, or once it is behind it again.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sim.fetch import expert as X

BEHIND_M = 0.06  # the gripper lines up this far behind the puck, on the line to the goal
ABOVE_M = 0.1  # and travels this high over the puck until it is there (its fingers hang low)
ARRIVES_M = 0.02  # a slide that ends this close to the goal (along the way) needs no strike
NEAR_M = 0.1  # a gripper this close to a sliding puck keeps still (the strike's follow-through)
MAX_TURN_RAD = 0.4
HOLD = np.array([0.0, 0.0, 0.0, -1.0], np.float32)  # the mocap stays where the gripper is


def _way(obj: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, float]:
    to = goal[:2] - obj[:2]
    dist = float(np.linalg.norm(to))
    return to / max(dist, 1e-9), dist


def strike(grip: np.ndarray, obj: np.ndarray, goal: np.ndarray, force: float, turn: float):
    """float32 (4,): the gripper driven at `force` (0..1 of its top speed) along the way to
    the goal turned by `turn` (radians), at the puck's height."""
    way, _ = _way(obj, goal)
    c, s = np.cos(turn), np.sin(turn)
    a = np.zeros(4)
    a[:2] = force * np.array([c * way[0] - s * way[1], s * way[0] + c * way[1]])
    a[2] = X.GAIN * (obj[2] - grip[2])
    a[3] = -1.0
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def slide(
    grip: np.ndarray,
    obj: np.ndarray,
    goal: np.ndarray,
    vel: np.ndarray,
    reach: Callable[[float | None, float], float],
    heading: Callable[[float], float | None],
) -> np.ndarray:
    """One action. reach(force, turn): how far along the way to the goal the puck is at the
    last step if the gripper strikes once (force None: does not) and then keeps still;
    heading(turn): the puck's heading off that way just after a full strike turned by `turn`
    (None: the strike does not reach it)."""
    way, dist = _way(obj, goal)
    rel = grip[:2] - obj[:2]
    along = float(np.dot(rel, way))
    across = float(np.linalg.norm(rel - along * way))
    low = grip[2] < obj[2] + 0.015
    moving = float(np.linalg.norm(vel[:2])) > 0.02
    in_place = along < -0.02 and across < 0.03 and low
    behind = obj[:2] - BEHIND_M * way
    if moving or in_place:
        if reach(None, 0.0) > dist - ARRIVES_M:  # it will come to the goal: keep still
            return HOLD.copy()
        if in_place:
            turn = _aim(heading)
            return strike(grip, obj, goal, _force(lambda f: reach(f, turn), dist), turn)
        if float(np.linalg.norm(rel)) < NEAR_M:
            return HOLD.copy()
    if np.linalg.norm(grip[:2] - behind) < 0.015:  # over the spot: down
        return X.move(np.append(behind, obj[2]), grip, -1.0)
    if low:  # beside the puck, low: up first, clear of it
        return X.move(np.append(grip[:2], obj[2] + ABOVE_M), grip, -1.0)
    return X.move(np.append(behind, obj[2] + ABOVE_M), grip, -1.0)


def _force(reach: Callable[[float], float], dist: float) -> float:
    """The strike force (0..1) whose slide ends nearest the goal, by bisection on the force
    (the slide grows with it, though not smoothly: a shade more force can carry the puck
    several centimetres further)."""
    tried = {1.0: reach(1.0)}
    lo, hi = 0.0, 1.0
    if tried[hi] > dist:
        for _ in range(6):
            mid = (lo + hi) / 2
            tried[mid] = reach(mid)
            lo, hi = (mid, hi) if tried[mid] < dist else (lo, mid)
    return min(tried, key=lambda f: (abs(tried[f] - dist), f))


def _aim(heading: Callable[[float], float | None]) -> float:
    """The turn (within MAX_TURN_RAD) whose strike heads the puck most nearly at the goal."""
    turn, best = 0.0, None
    for _ in range(3):
        off = heading(turn)
        if off is None:
            break
        if best is None or abs(off) < abs(best[1]):
            best = (turn, off)
        if abs(off) < 0.005:
            break
        turn = float(np.clip(turn - off, -MAX_TURN_RAD, MAX_TURN_RAD))
    return 0.0 if best is None else best[0]


def act(world, scene) -> np.ndarray:
    """The demonstrator's action in `scene` of a FetchSlide world, its predictions stepped
    through the world itself."""
    with world._lock:
        data = world.restore(scene).data
        grip = np.array(data.site("robot0:grip").xpos)
        obj = np.array(data.site("object0").xpos)
        vel = np.array(data.joint("object0:joint").qvel[:3])
    goal = world.goal_of(scene)
    way, _ = _way(obj, goal)

    def after(force: float | None, turn: float, steps: int | None):
        s = scene
        if force is not None:
            s = world.step_batch([s], strike(grip, obj, goal, force, turn)[None])[0]
        k = 0
        while not world.done(s) and (steps is None or k < steps):
            s, k = world.step_batch([s], HOLD[None])[0], k + 1
        return s

    def reach(force: float | None, turn: float) -> float:
        end = np.asarray(after(force, turn, None).obj("object").pos[:2])
        return float(np.dot(end - obj[:2], way))

    def heading(turn: float) -> float | None:
        with world._lock:
            v = np.array(world.restore(after(1.0, turn, 2)).data.joint("object0:joint").qvel[:2])
        if np.linalg.norm(v) < 0.05:
            return None
        return float(np.arctan2(way[0] * v[1] - way[1] * v[0], np.dot(way, v)))

    return slide(grip, obj, goal, vel, reach, heading)
