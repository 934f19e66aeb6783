"""The 29 VIMA shapes as 2D footprints (shapely) and their sizes in metres.

Every outline is centred on its footprint's bounding box (the pan on its disc) with x to the
right and y up on the table. The 3D meshes built from these live in sim.tabletop.meshes.
"""

from __future__ import annotations

import math

from shapely import affinity
from shapely.geometry import LineString, Point, Polygon, box
from shapely.ops import unary_union

from sim.tabletop.catalogue import GOALS, MANIPULATED, SHAPES

__all__ = ["GOALS", "MANIPULATED", "SHAPES", "kit_outline", "outline"]

KIT_HEIGHT_M = 0.03  # thickness of the extruded kit shapes (letters .. L-shaped block)
# Largest footprint extent of each kit shape (VIMA: 0.08 m scaled by 1.6 or 1.8).
KIT_SIZE_M: dict[str, float] = {
    **{f"letter {c}": 0.144 for c in "AEGMRTV"},
    "letter M": 0.136,
    "cross": 0.128,
    "diamond": 0.128,
    "triangle": 0.128,
    "flower": 0.144,
    "heart": 0.144,
    "hexagon": 0.136,
    "pentagon": 0.136,
    "star": 0.144,
    "ring": 0.128,
    "round": 0.128,
    "L-shaped block": 0.128,
}
# Boxes (x, y, z) in metres. The shorter block is wider than the block so that the two differ
# seen from straight above (an orthographic top-down view cannot show height).
BOX_SIZE_M: dict[str, tuple[float, float, float]] = {
    "block": (0.07, 0.07, 0.07),
    "shorter block": (0.10, 0.07, 0.03),
    "small block": (0.03, 0.03, 0.03),
    "line": (0.25, 0.04, 0.008),
}
SQUARE_M = (0.18, 0.03, 0.02)  # outer side, border width, height
FRAME_M = (0.225, 0.015, 0.006)
THREE_SIDED_M = (0.20, 0.14, 0.02, 0.02)  # outer x, outer y, border, height (open towards +y)
CONTAINER_M = (0.16, 0.012, 0.05, 0.01)  # outer side, wall, height, base thickness
BOWL_M = (0.085, 0.045, 0.06, 0.006)  # rim radius, base radius, height, wall thickness
PALLET_M = (0.21, 0.175, 0.035)
PAN_M = (0.08, 0.008, 0.03, 0.006)  # radius, base thickness, rim height, rim thickness
PAN_HANDLE_M = (0.07, 0.022, 0.012)  # length (along +x from the rim), width, thickness


def _strokes(lines: list[list[tuple[float, float]]], width: float) -> Polygon:
    """Union of polylines drawn with a flat pen of `width`, in a unit box, clipped to it."""
    parts = [
        LineString(p).buffer(width / 2, cap_style="flat", join_style="mitre", mitre_limit=3.0)
        for p in lines
    ]
    return unary_union(parts).intersection(box(-0.5, -0.5, 0.5, 0.5))


def _arc(cx: float, cy: float, r: float, a0: float, a1: float, n: int = 24) -> list:
    return [
        (cx + r * math.cos(math.radians(a)), cy + r * math.sin(math.radians(a)))
        for a in (a0 + (a1 - a0) * i / n for i in range(n + 1))
    ]


def _letter(c: str) -> Polygon:
    w = 0.22
    if c == "A":
        return _strokes(
            [[(-0.5, -0.55), (0.0, 0.55), (0.5, -0.55)], [(-0.25, -0.12), (0.25, -0.12)]], w
        )
    if c == "E":
        x0 = -0.5 + w / 2
        return _strokes(
            [
                [(0.45, 0.5 - w / 2), (x0, 0.5 - w / 2), (x0, -0.5 + w / 2), (0.45, -0.5 + w / 2)],
                [(x0, 0.0), (0.3, 0.0)],
            ],
            w,
        )
    if c == "G":
        return _strokes(
            [_arc(0.0, 0.0, 0.5 - w / 2, 40, 360), [(0.05, 0.0), (0.5 - w / 2, 0.0)]], w
        )
    if c == "M":
        x0, x1 = -0.5 + w / 2, 0.5 - w / 2
        return _strokes([[(x0, -0.5), (x0, 0.5), (0.0, -0.15), (x1, 0.5), (x1, -0.5)]], w)
    if c == "R":
        x0 = -0.5 + w / 2
        bowl = [(x0, 0.5 - w / 2), (0.1, 0.5 - w / 2)]
        bowl += _arc(0.1, 0.25 - w / 4, 0.25 - w / 4, 90, -90)[1:]
        bowl += [(x0, 0.0)]
        return _strokes([[(x0, -0.5), (x0, 0.5)], bowl, [(-0.05, 0.0), (0.5, -0.55)]], w)
    if c == "T":
        return _strokes([[(-0.5, 0.5 - w / 2), (0.5, 0.5 - w / 2)], [(0.0, 0.5), (0.0, -0.5)]], w)
    if c == "V":
        return _strokes([[(-0.5, 0.55), (0.0, -0.55), (0.5, 0.55)]], w)
    raise ValueError(c)


def _regular(n: int, r: float = 0.5, rot_deg: float = 90.0) -> Polygon:
    return Polygon(
        [
            (
                r * math.cos(math.radians(rot_deg + 360 * i / n)),
                r * math.sin(math.radians(rot_deg + 360 * i / n)),
            )
            for i in range(n)
        ]
    )


def _kit_unit(name: str) -> Polygon:
    """The kit shape in unit coordinates (any scale; normalised by the caller)."""
    if name.startswith("letter "):
        return _letter(name[-1])
    if name == "cross":
        return unary_union([box(-0.5, -0.17, 0.5, 0.17), box(-0.17, -0.5, 0.17, 0.5)])
    if name == "diamond":
        return Polygon([(0, 0.5), (0.36, 0), (0, -0.5), (-0.36, 0)])
    if name == "triangle":
        return _regular(3)
    if name == "flower":
        petals = [
            Point(0.27 * math.cos(a), 0.27 * math.sin(a)).buffer(0.23, 8)
            for a in (0, 1.5708, 3.1416, 4.7124)
        ]
        return unary_union([*petals, Point(0, 0).buffer(0.25, 8)])
    if name == "heart":
        ts = [2 * math.pi * i / 96 for i in range(96)]
        return Polygon(
            [
                (
                    16 * math.sin(t) ** 3,
                    13 * math.cos(t) - 5 * math.cos(2 * t) - 2 * math.cos(3 * t) - math.cos(4 * t),
                )
                for t in ts
            ]
        )
    if name == "hexagon":
        return _regular(6, rot_deg=0.0)
    if name == "pentagon":
        return _regular(5)
    if name == "star":
        pts = []
        for i in range(10):
            r = 0.5 if i % 2 == 0 else 0.2
            a = math.radians(90 + 36 * i)
            pts.append((r * math.cos(a), r * math.sin(a)))
        return Polygon(pts)
    if name == "ring":
        return Point(0, 0).buffer(0.5, 12).difference(Point(0, 0).buffer(0.27, 12))
    if name == "round":
        return Point(0, 0).buffer(0.5, 12)
    if name == "L-shaped block":
        return Polygon([(0, 0), (1, 0), (1, 0.36), (0.36, 0.36), (0.36, 1), (0, 1)])
    raise ValueError(name)


def kit_outline(name: str) -> Polygon:
    """Footprint of a kit shape in metres, centred on its bounding box, largest extent as in
    KIT_SIZE_M."""
    poly = _kit_unit(name)
    x0, y0, x1, y1 = poly.bounds
    poly = affinity.translate(poly, -(x0 + x1) / 2, -(y0 + y1) / 2)
    s = KIT_SIZE_M[name] / max(x1 - x0, y1 - y0)
    return affinity.scale(poly, s, s, origin=(0, 0))


def outline(side_x: float, side_y: float, border: float, *, open_top: bool = False) -> Polygon:
    """A rectangular outline of `border` width; `open_top` leaves the +y side open."""
    outer = box(-side_x / 2, -side_y / 2, side_x / 2, side_y / 2)
    top = side_y / 2 + (border if open_top else -border)
    inner = box(-side_x / 2 + border, -side_y / 2 + border, side_x / 2 - border, top)
    return outer.difference(inner)
