"""Scripted demonstrators for robosuite's Lift and Stack: closed-loop on the state, one action
per control step.

Actions are the OSC controller's own 7: (dx, dy, dz) of the end effector (1 = 0.05 m), a
rotation (left at zero: the hand keeps its orientation) and the gripper (+1 close, -1 open),
each in [-1, 1]. Whether the gripper holds an object is the environment's own grasp check (both
finger pads touching it).
"""

from __future__ import annotations

import numpy as np

GAIN = 30.0  # action per metre of error (saturates at 0.033 m)
HOVER_M = 0.08  # the hand comes down onto the object as it lines up over it
GRASP_M = 0.012  # closer than this to the object's centre, the fingers close
LIFT_M = 0.15  # a lifted object is raised this far above where it was grasped
CARRY_M = 0.08  # a carried cube crosses this high above the cube it goes on
ALIGNED_M = 0.006  # over the other cube within this: the carried cube comes down
RELEASE_M = 0.006  # this close above its resting place, the carried cube is let go
PLACING_M = 0.02  # this close above it (and over the other cube), it is being set down


def move(to: np.ndarray, eef: np.ndarray, gripper: float) -> np.ndarray:
    a = np.zeros(7)
    a[:3] = GAIN * (to - eef)
    a[6] = gripper
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def _pick(eef: np.ndarray, obj: np.ndarray) -> np.ndarray:
    """Over the object, down onto it (coming lower as it lines up), close on it."""
    d = obj - eef
    if np.linalg.norm(d) < GRASP_M:
        return move(obj, eef, 1.0)
    hover = min(HOVER_M, 4.0 * float(np.linalg.norm(d[:2])))
    return move(obj + np.array([0.0, 0.0, hover]), eef, -1.0)


def lift(eef: np.ndarray, objs: list[np.ndarray], held: bool, table_z: float) -> np.ndarray:
    """Pick the cube and raise it LIFT_M."""
    (cube,) = objs
    if held:
        return move(np.array([eef[0], eef[1], table_z + LIFT_M]), eef, 1.0)
    return _pick(eef, cube)


def stack(
    eef: np.ndarray, objs: list[np.ndarray], held: bool, table_z: float, rest_dz: float
) -> np.ndarray:
    """Pick cube A, carry it over cube B, set it down on B (A's centre `rest_dz` over B's),
    let go and rise."""
    a, b = objs
    rest = b + np.array([0.0, 0.0, rest_dz])
    offset = eef - a  # where the hand is, relative to the cube it holds
    if held:
        off = float(np.linalg.norm(a[:2] - b[:2]))
        if a[2] < rest[2] + PLACING_M and off < 2 * ALIGNED_M:  # setting it down
            if a[2] - rest[2] > RELEASE_M:
                return move(rest + offset, eef, 1.0)
            return move(eef, eef, -1.0)
        if off > ALIGNED_M:  # over the table at carrying height
            carry = np.array([*b[:2], b[2] + rest_dz + CARRY_M])
            if a[2] < carry[2] - 0.02 and off > 0.02:
                carry[:2] = a[:2]  # straight up first
            return move(carry + offset, eef, 1.0)
        return move(rest + offset, eef, 1.0)
    if np.linalg.norm(a - rest) < 0.01:  # resting on B: let go, then up
        return move(np.array([*eef[:2], rest[2] + CARRY_M]), eef, -1.0)
    return _pick(eef, a)
