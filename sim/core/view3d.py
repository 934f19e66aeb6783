"""A world's 3D scene, for the worlds that have one (World.view3d): what the recorder and the
page need to draw each object's mesh at its pose, and the poses over simulated time while an
action plays out."""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.core.scene import Scene


@dataclass(frozen=True)
class ObjectPose:
    """One present object (or one rigid part of it, e.g. a finger of the gripper): its shape (a
    name `View3D.mesh` knows), colour name and display RGBA in [0, 1], position (3,) metres and
    orientation quat (w, x, y, z) of its body frame, in the world's frame."""

    slot: str
    shape: str
    colour: str
    rgba: tuple[float, float, float, float]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]


@dataclass(frozen=True, eq=False)
class Frames:
    """Poses of the present objects over simulated time during one action.

    slots: the present slots, in order; times_s: float (F,); pos: float (F, K, 3) metres;
    quat: float (F, K, 4) (w, x, y, z); picked: the carried slot, if any.
    """

    slots: tuple[str, ...]
    times_s: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    picked: str | None


@dataclass(frozen=True)
class Look:
    """How a colour is drawn on a mesh: a plain RGBA, or a texture image tiled from above."""

    rgba: tuple[float, float, float, float]
    texture: np.ndarray | None = None
    """uint8 (P, P, 3) of one tile, or None for a plain colour."""
    tile_m: float = 1.0
    """Metres of surface one texture tile covers."""


class View3D(abc.ABC):
    """The 3D scene of a world: objects with meshes at their poses, around `centre_m`.

    Two kinds of action: a view that `plays_actions` (the tabletop's pick-and-place: one action
    is seconds of simulated carry and settling) gives the poses through each action
    (`frames`); a closed-loop one (the MuJoCo worlds: one action is one short control step)
    does not, its poses at each step being the rollout."""

    centre_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The point the views are centred on and look at (the table top's centre), metres."""
    view_half_m: float
    """Half the side of the square around centre_m that the views frame (the tabletop's: the
    square of the table its top-down camera, the rendered frame, sees)."""
    table_half_m: float | None = None
    """The table top is the square centre_m + [-table_half_m, table_half_m]^2 at centre_m's z,
    drawn with the square its top-down camera sees; None: no table apart from the objects (a
    world whose table is one of its slots draws it as one), and no top-down camera."""
    table_thickness_m: float = 0.0
    table_rgb: tuple[int, int, int] = (0, 0, 0)
    plays_actions: bool = False
    """`frames` plays an action out over simulated time (False: a closed-loop view, whose
    poses at each step are the rollout)."""

    @abc.abstractmethod
    def poses(self, scene: Scene) -> list[ObjectPose]:
        """The present objects of a scene, in slot order."""

    @abc.abstractmethod
    def mesh(self, shape: str):
        """The mesh of a shape (a trimesh.Trimesh, metres, in its body frame; the tabletop's:
        bottom at z = 0)."""

    @abc.abstractmethod
    def look(self, shape: str, colour: str) -> Look:
        """How `colour` is drawn on `shape`."""

    @abc.abstractmethod
    def arrow(
        self, scene: Scene, action: Sequence[float], after: Scene
    ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """How `action`, taken in `scene` (giving `after`), is drawn: an arrow's (origin,
        vector), metres (the tabletop's: from the pick point to the place point, above the
        table; a closed-loop view's: the end effector's motion)."""

    def frames(self, scene: Scene, action: Sequence[float], *, every: int) -> Frames:
        """The objects' poses every `every` physics steps while `action` plays out (views that
        `plays_actions` only)."""
        raise NotImplementedError(f"{type(self).__name__} does not play actions out")
