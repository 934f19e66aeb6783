"""The 65 textures of the VIMA set, generated with numpy (no image files).

Each texture is uint8 (TEX_PX, TEX_PX, 3), tiling seamlessly, and covers TEX_M metres of an
object's top face (planar projection from above).
"""

from __future__ import annotations

import colorsys
import zlib
from functools import lru_cache

import numpy as np

from sim.tabletop.colours import NAMED_TEXTURES, PATTERN_COLOURS, PLAIN_RGB, TEXTURES

TEX_PX = 64
TEX_M = 0.12  # metres of table covered by one tile of a texture

_v, _u = np.meshgrid(np.arange(TEX_PX) / TEX_PX, np.arange(TEX_PX) / TEX_PX, indexing="ij")


def _rng(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


def _smooth_noise(rng: np.random.Generator, cells: int) -> np.ndarray:
    """Tileable value noise in [0, 1]: float (TEX_PX, TEX_PX), `cells` lattice cells a side."""
    lattice = rng.random((cells, cells))
    x, y = _u * cells, _v * cells
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    x1, y1 = (x0 + 1) % cells, (y0 + 1) % cells
    top = lattice[y0, x0] * (1 - fx) + lattice[y0, x1] * fx
    bot = lattice[y1, x0] * (1 - fx) + lattice[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def _mix(mask: np.ndarray, a, b) -> np.ndarray:
    """Per pixel: a where mask is 1, b where 0 (float mask allowed) -> float (H, W, 3)."""
    m = np.asarray(mask, float)[..., None]
    return m * np.asarray(a, float) + (1 - m) * np.asarray(b, float)


def _lighter(rgb, amount: float = 0.55) -> np.ndarray:
    return np.asarray(rgb, float) + (255 - np.asarray(rgb, float)) * amount


def _named(name: str) -> np.ndarray:
    rng = _rng(name)
    if name == "brick":
        row = np.floor(_v * 4)
        x = (_u * 2 + 0.5 * (row % 2)) % 1.0
        mortar = ((_v * 4) % 1.0 < 0.12) | (x < 0.06)
        tone = 0.85 + 0.3 * _smooth_noise(rng, 8)[..., None]
        return _mix(mortar, (205, 200, 190), np.array((165, 70, 55)) * tone)
    if name == "tiles":
        grout = ((_u * 4) % 1.0 < 0.1) | ((_v * 4) % 1.0 < 0.1)
        return _mix(grout, (95, 95, 100), (232, 232, 222))
    if name == "wooden":
        grain = np.sin(2 * np.pi * (6 * _u + 0.6 * _smooth_noise(rng, 4))) * 0.5 + 0.5
        return _mix(grain, (214, 172, 120), (168, 118, 70))
    if name == "granite":
        n = _smooth_noise(rng, 16) * 0.5 + rng.random((TEX_PX, TEX_PX)) * 0.5
        return np.repeat((90 + 90 * n)[..., None], 3, axis=2)
    if name == "plastic":
        n = _smooth_noise(rng, 4)
        return _mix(n, (70, 200, 230), (30, 120, 200))
    if name == "polka dot":
        d = np.hypot((_u * 3) % 1.0 - 0.5, (_v * 3) % 1.0 - 0.5)
        return _mix(d < 0.28, (20, 20, 20), (245, 245, 245))
    if name == "checkerboard":
        return _mix((np.floor(_u * 4) + np.floor(_v * 4)) % 2, (15, 15, 15), (240, 240, 240))
    if name == "tiger":
        w = np.sin(2 * np.pi * (3 * _u + 0.35 * np.sin(2 * np.pi * _v))) + 0.8 * (
            _smooth_noise(rng, 4) - 0.5
        )
        return _mix(w > 0.55, (25, 20, 15), (240, 135, 30))
    if name == "magma":
        n = _smooth_noise(rng, 4) * 0.6 + _smooth_noise(rng, 8) * 0.4
        vein = np.clip(1 - np.abs(n - 0.5) * 8, 0, 1)
        return _mix(vein, (255, 170, 40), np.array((70, 10, 10)) + 60 * n[..., None])
    if name == "rainbow":
        hue = (_u + 0.5 * _v) % 1.0
        rgb = np.vectorize(colorsys.hsv_to_rgb, otypes=[float, float, float])(hue, 0.9, 0.95)
        return np.stack(rgb, axis=-1) * 255
    raise ValueError(name)


def _pattern(name: str) -> np.ndarray:
    dark = name.startswith("dark ")
    words = name.removeprefix("dark ").split(" ")
    rgb = {c: PLAIN_RGB[("dark " if dark else "") + c] for c in PATTERN_COLOURS}
    if name.endswith("stripe"):  # "<a> and <b> stripe": diagonal bands, two per tile
        a, b = rgb[words[0]], rgb[words[2]]
        return _mix(((_u + _v) * 2) % 1.0 < 0.5, a, b)
    if name.endswith("polka dot"):  # background <a>, dots <b>, 2 x 2 per tile
        a, b = rgb[words[0]], rgb[words[2]]
        d = np.hypot((_u * 2) % 1.0 - 0.5, (_v * 2) % 1.0 - 0.5)
        return _mix(d < 0.3, b, a)
    if name.endswith("swirl"):  # <a> with a lighter spiral, one per tile
        a = rgb[words[0]]
        dx, dy = _u - 0.5, _v - 0.5
        r, ang = np.hypot(dx, dy), np.arctan2(dy, dx)
        s = np.sin(2 * ang + 14 * r) * np.clip(1.2 - r * 1.6, 0, 1)
        return _mix(s > 0.25, _lighter(a), a)
    if name.endswith("paisley"):  # <a> with lighter teardrops, a darker eye in each
        a = rgb[words[0]]
        out = np.empty((TEX_PX, TEX_PX, 3))
        out[:] = a
        for cx, cy, rot in (
            (0.28, 0.3, 0.6),
            (0.75, 0.72, 3.7),
            (0.78, 0.22, 2.1),
            (0.25, 0.8, 5.0),
        ):
            dx = (_u - cx + 0.5) % 1.0 - 0.5
            dy = (_v - cy + 0.5) % 1.0 - 0.5
            x = dx * np.cos(rot) + dy * np.sin(rot)
            y = -dx * np.sin(rot) + dy * np.cos(rot)
            r = np.hypot(x, y)
            drop = r < 0.21 * (0.6 + 0.4 * np.cos(np.arctan2(y, x)))
            out = _mix(drop, _lighter(a, 0.6), out)
            out = _mix(r < 0.05, np.asarray(a) * 0.55, out)
        return out
    raise ValueError(name)


@lru_cache(maxsize=len(TEXTURES))
def texture(name: str) -> np.ndarray:
    """uint8 (TEX_PX, TEX_PX, 3) image of a texture, rows from +y (top) to -y."""
    if name not in TEXTURES:
        raise ValueError(f"unknown texture {name!r}; accepted: {', '.join(TEXTURES)}")
    img = _named(name) if name in NAMED_TEXTURES else _pattern(name)
    img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    img.flags.writeable = False
    return img


def mean_rgb(name: str) -> tuple[int, int, int]:
    """The mean colour of an appearance (its plain RGB, or its texture's average)."""
    if name in PLAIN_RGB:
        return PLAIN_RGB[name]
    r, g, b = np.rint(texture(name).reshape(-1, 3).mean(axis=0)).astype(int).tolist()
    return (r, g, b)
