"""Scripted demonstrators for the Fetch tasks: closed-loop on the state, one action per step.

Actions are Fetch's own: (dx, dy, dz) of the gripper (scaled by 0.05 m in the env) and the
fingers (+1 open, -1 close), each in [-1, 1].
"""

from __future__ import annotations

import numpy as np

GAIN = 10.0  # action per metre of error (saturates at 0.1 m)
HOVER_M = 0.06  # the gripper comes down onto the object as it lines up under it
GRASP_M = 0.012  # closer than this to the object's centre, the fingers close
LINED_UP_M = 0.01  # this near over the object (x, y), the gripper goes all the way down and
# grips: without it a gripper a few mm off (noise, a cloned policy's error) hovered over the
# block for good (the hover height shrank with the offset but never let it within GRASP_M)
HELD_M = 0.02  # within this of the gripper, with the fingers closed, the object is held
CLOSED_WIDTH_M = 0.055  # finger opening below which the fingers count as closed on the block
CARRY_Z_M = 0.52  # a carried object crosses the table this high (its top is at 0.4 m)
ARRIVED_M = 0.02  # over the goal: the carried object comes down (or up) to it
PUSH_BEHIND_M = 0.06  # the pusher lines up this far behind the object, away from the goal
PUSH_STEP_M = 0.03  # how far past the object's back face the pusher aims each step
PUSH_LIFT_M = 0.06  # and travels this high over the table until it is there


def move(to: np.ndarray, grip: np.ndarray, fingers: float) -> np.ndarray:
    a = np.zeros(4)
    a[:3] = GAIN * (to - grip)
    a[3] = fingers
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def pick_and_place(grip: np.ndarray, obj: np.ndarray, goal: np.ndarray, width: float) -> np.ndarray:
    """Over the object, down onto it, close, lift it clear of the table, carry it over the
    goal and set it there."""
    d = obj - grip
    if np.linalg.norm(d) < HELD_M and width < CLOSED_WIDTH_M:
        far = float(np.linalg.norm(goal[:2] - obj[:2]))
        # as high over the goal's height as the goal is far across (a funnel, not a corner to
        # turn: a policy a centimetre off still comes down), at most the carrying height
        height = max(goal[2], min(CARRY_Z_M, goal[2] + far))
        to = np.array([goal[0], goal[1], height])
        if obj[2] < min(height, CARRY_Z_M) - 0.02 and far > ARRIVED_M:  # up off the table first
            to = np.array([obj[0], obj[1], height])
        return move(to + (grip - obj), grip, -1.0)
    off = float(np.linalg.norm(d[:2]))
    hover = min(HOVER_M, 4.0 * max(0.0, off - LINED_UP_M))
    above = obj + np.array([0.0, 0.0, hover])
    grasp = np.linalg.norm(d) < GRASP_M or (off < LINED_UP_M and abs(d[2]) < GRASP_M)
    return move(above, grip, -1.0 if grasp else 1.0)


def push(grip: np.ndarray, obj: np.ndarray, goal: np.ndarray, width: float) -> np.ndarray:
    """Fingers closed: over the spot behind the object (seen from the goal), down beside it,
    then along the line through it until its centre is on the goal."""
    way = goal[:2] - obj[:2]
    if np.linalg.norm(way) < 1e-6:
        return move(grip, grip, -1.0)
    way = way / np.linalg.norm(way)
    rel = grip[:2] - obj[:2]
    along = float(np.dot(rel, way))
    across = float(np.linalg.norm(rel - along * way))
    behind = np.append(obj[:2] - PUSH_BEHIND_M * way, obj[2])
    low = grip[2] < obj[2] + 0.015
    if np.linalg.norm(goal[:2] - obj[:2]) < 0.01:  # there: hold still
        return move(grip, grip, -1.0)
    if along < -0.02 and across < 0.02 and low:  # in place: nudge it along the line
        step = min(PUSH_STEP_M, 0.5 * float(np.linalg.norm(goal[:2] - obj[:2])))
        return move(np.append(obj[:2] - (0.03 - step) * way, obj[2]), grip, -1.0)
    if np.linalg.norm(grip[:2] - behind[:2]) < 0.015:  # over the spot: down beside the object
        return move(behind, grip, -1.0)
    return move(behind + np.array([0.0, 0.0, PUSH_LIFT_M]), grip, -1.0)


def reach(grip: np.ndarray, obj: np.ndarray | None, goal: np.ndarray, width: float) -> np.ndarray:
    """The gripper to the goal."""
    return move(goal, grip, 1.0)
