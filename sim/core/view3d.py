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
    """One present object: its shape (a name `View3D.mesh` knows), colour name and display RGBA
    in [0, 1], position (3,) metres and orientation quat (w, x, y, z) of its body frame."""

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
    """The 3D scene of a world: a table top seen from above, objects with meshes on it."""

    table_half_m: float
    """The table top is the square [-table_half_m, table_half_m]^2 at z = 0."""
    table_thickness_m: float
    table_rgb: tuple[int, int, int]
    view_half_m: float
    """The square of the table the camera (the rendered frame) sees."""

    @abc.abstractmethod
    def poses(self, scene: Scene) -> list[ObjectPose]:
        """The present objects of a scene, in slot order."""

    @abc.abstractmethod
    def mesh(self, shape: str):
        """The mesh of a shape (a trimesh.Trimesh, metres, bottom at z = 0)."""

    @abc.abstractmethod
    def look(self, colour: str) -> Look:
        """How `colour` is drawn."""

    @abc.abstractmethod
    def frames(self, scene: Scene, action: Sequence[float], *, every: int) -> Frames:
        """The objects' poses every `every` physics steps while `action` plays out."""
