"""3D geometry of the 29 shapes: display meshes, collision primitives and footprints.

One place for the simulator, the recorder and the web page. Every mesh is in its object's body
frame: bottom at z = 0, footprint centred on x = y = 0 (the pan on its disc), metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from shapely.geometry import MultiPoint, Point

from sim.tabletop import shapes as S


@dataclass(frozen=True)
class Prim:
    """A MuJoCo collision primitive in the body frame.

    kind: "box" (size = half extents) or "cylinder" (size = radius, half height, 0).
    pos: centre (3,) in metres; quat: orientation (w, x, y, z).
    """

    kind: str
    size: tuple[float, float, float]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


def _box(extents, centre) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(centre)
    return m


def _extrude(poly, height: float, z0: float = 0.0) -> trimesh.Trimesh:
    m = trimesh.creation.extrude_polygon(poly, height)
    m.apply_translation((0.0, 0.0, z0))
    return m


def _bowl() -> trimesh.Trimesh:
    rim, base, h, t = S.BOWL_M
    # closed profile in (radius, z), revolved about the z axis
    profile = np.array([(0.0, 0.0), (base, 0.0), (rim, h), (rim - t, h), (base - t, t), (0.0, t)])
    return trimesh.creation.revolve(profile, sections=48)


def _pan() -> trimesh.Trimesh:
    r, base_t, rim_h, rim_t = S.PAN_M
    length, width, thick = S.PAN_HANDLE_M
    disc = trimesh.creation.cylinder(radius=r, height=base_t, sections=48)
    disc.apply_translation((0.0, 0.0, base_t / 2))
    rim = _extrude(Point(0, 0).buffer(r, 12).difference(Point(0, 0).buffer(r - rim_t, 12)), rim_h)
    handle = _box((length, width, thick), (r + length / 2 - rim_t / 2, 0.0, rim_h - thick / 2))
    return trimesh.util.concatenate([disc, rim, handle])


def _pallet() -> trimesh.Trimesh:
    sx, sy, h = S.PALLET_M
    deck_t, n_slats, slat_w = 0.01, 5, 0.027
    parts = []
    for i in range(n_slats):  # deck boards along x, spread over y
        y = -sy / 2 + slat_w / 2 + i * (sy - slat_w) / (n_slats - 1)
        parts.append(_box((sx, slat_w, deck_t), (0.0, y, h - deck_t / 2)))
    for x in (-sx / 2 + 0.015, 0.0, sx / 2 - 0.015):  # runners along y, under the deck
        parts.append(_box((0.03, sy, h - deck_t), (x, 0.0, (h - deck_t) / 2)))
    return trimesh.util.concatenate(parts)


def _container() -> trimesh.Trimesh:
    side, wall, h, base_t = S.CONTAINER_M
    walls = _extrude(S.outline(side, side, wall), h)
    base = _box((side - 2 * wall, side - 2 * wall, base_t), (0.0, 0.0, base_t / 2))
    return trimesh.util.concatenate([walls, base])


def _build(name: str) -> trimesh.Trimesh:
    if name in S.KIT_SIZE_M:
        return _extrude(S.kit_outline(name), S.KIT_HEIGHT_M)
    if name in S.BOX_SIZE_M:
        ex = S.BOX_SIZE_M[name]
        return _box(ex, (0.0, 0.0, ex[2] / 2))
    if name == "square":
        side, border, h = S.SQUARE_M
        return _extrude(S.outline(side, side, border), h)
    if name == "frame":
        side, border, h = S.FRAME_M
        return _extrude(S.outline(side, side, border), h)
    if name == "three-sided rectangle":
        sx, sy, border, h = S.THREE_SIDED_M
        return _extrude(S.outline(sx, sy, border, open_top=True), h)
    if name == "container":
        return _container()
    if name == "bowl":
        return _bowl()
    if name == "pallet":
        return _pallet()
    if name == "pan":
        return _pan()
    raise ValueError(f"unknown shape {name!r}; accepted: {', '.join(S.SHAPES)}")


@lru_cache(maxsize=len(S.SHAPES))
def shape_mesh(name: str) -> trimesh.Trimesh:
    """The display mesh of a shape (body frame, metres). Cached; do not modify the result."""
    m = _build(name)
    m.merge_vertices()
    return m


def _quat_axis(axis, angle: float) -> tuple[float, float, float, float]:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    s = math.sin(angle / 2)
    return (math.cos(angle / 2), *(float(a) * s for a in axis))


def _qmul(a, b) -> tuple[float, float, float, float]:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


def _ring_walls(r_in: float, r_out: float, h: float, t: float, n: int, z0: float = 0.0) -> list:
    """n boxes approximating a (possibly sloped) round wall from radius r_in at z0 to r_out at
    z0 + h, of thickness t."""
    tilt = math.atan2(r_out - r_in, h)
    length = math.hypot(r_out - r_in, h)
    r_mid = (r_in + r_out) / 2 + t / 2 * math.cos(tilt)
    half_w = math.pi * max(r_in, r_out) / n * 1.05
    prims = []
    for i in range(n):
        a = 2 * math.pi * i / n
        # tilt outwards about the tangent, then turn to azimuth a
        q = _qmul(_quat_axis((0, 0, 1), a), _quat_axis((0, 1, 0), tilt))
        pos = (r_mid * math.cos(a), r_mid * math.sin(a), z0 + h / 2)
        prims.append(Prim("box", (t / 2, half_w, length / 2), pos, q))
    return prims


def _outline_boxes(
    sx: float, sy: float, border: float, h: float, *, open_top=False, z0: float = 0.0
) -> list:
    """Boxes of a rectangular outline from z0 up to h; the two x sides span the y sides' gap."""
    hx, hy, hb, hh = sx / 2, sy / 2, border / 2, (h - z0) / 2
    zc = z0 + hh
    prims = [
        Prim("box", (hx, hb, hh), (0.0, -hy + hb, zc)),
        Prim("box", (hb, hy, hh), (-hx + hb, 0.0, zc)),
        Prim("box", (hb, hy, hh), (hx - hb, 0.0, zc)),
    ]
    if not open_top:
        prims.append(Prim("box", (hx, hb, hh), (0.0, hy - hb, zc)))
    return prims


@lru_cache(maxsize=len(S.SHAPES))
def collision_prims(name: str) -> tuple[Prim, ...]:
    """Primitives for the shapes whose convex hull is a poor stand-in (hollow goals, boxes).

    Empty for the kit shapes: MuJoCo collides their display mesh through its convex hull.
    """
    if name in S.BOX_SIZE_M:
        ex = S.BOX_SIZE_M[name]
        return (Prim("box", (ex[0] / 2, ex[1] / 2, ex[2] / 2), (0.0, 0.0, ex[2] / 2)),)
    if name == "square":
        side, border, h = S.SQUARE_M
        return tuple(_outline_boxes(side, side, border, h))
    if name == "frame":
        side, border, h = S.FRAME_M
        return tuple(_outline_boxes(side, side, border, h))
    if name == "three-sided rectangle":
        sx, sy, border, h = S.THREE_SIDED_M
        return tuple(_outline_boxes(sx, sy, border, h, open_top=True))
    if name == "container":
        side, wall, h, base_t = S.CONTAINER_M
        base = Prim("box", (side / 2, side / 2, base_t / 2), (0.0, 0.0, base_t / 2))
        return (base, *_outline_boxes(side, side, wall, h, z0=base_t))
    if name == "bowl":
        rim, base, h, t = S.BOWL_M
        floor = Prim("cylinder", (base, t / 2, 0.0), (0.0, 0.0, t / 2))
        return (floor, *_ring_walls(base - t, rim - t, h - t, t, 12, z0=t))
    if name == "pallet":
        sx, sy, h = S.PALLET_M
        return (Prim("box", (sx / 2, sy / 2, h / 2), (0.0, 0.0, h / 2)),)
    if name == "pan":
        r, base_t, rim_h, rim_t = S.PAN_M
        length, width, thick = S.PAN_HANDLE_M
        floor = Prim("cylinder", (r, base_t / 2, 0.0), (0.0, 0.0, base_t / 2))
        handle = Prim(
            "box",
            (length / 2, width / 2, thick / 2),
            (r + length / 2 - rim_t / 2, 0.0, rim_h - thick / 2),
        )
        walls = _ring_walls(r - rim_t, r - rim_t, rim_h - base_t, rim_t, 12, z0=base_t)
        return (floor, handle, *walls)
    if name in S.KIT_SIZE_M:
        return ()
    raise ValueError(f"unknown shape {name!r}; accepted: {', '.join(S.SHAPES)}")


@lru_cache(maxsize=len(S.SHAPES))
def footprint_hull(name: str) -> np.ndarray:
    """Convex hull of the shape seen from above: float64 (N, 2) counter-clockwise, metres."""
    hull = MultiPoint(shape_mesh(name).vertices[:, :2]).convex_hull
    return np.asarray(hull.exterior.coords)[:-1]


def inertia(name: str, mass_kg: float) -> tuple[np.ndarray, np.ndarray]:
    """(centre of mass (3,), diagonal inertia (3,)) of a solid box the size of the shape."""
    lo, hi = shape_mesh(name).bounds
    ex = hi - lo
    diag = (
        mass_kg
        / 12
        * np.array([ex[1] ** 2 + ex[2] ** 2, ex[0] ** 2 + ex[2] ** 2, ex[0] ** 2 + ex[1] ** 2])
    )
    com = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.4 * ex[2]])
    return com, diag
