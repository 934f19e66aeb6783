"""The numpy renderer of 2D navigation: 36x36x3, black arena [-6, 6]^2, 3 pixels per unit."""

from __future__ import annotations

import functools

import numpy as np

SIZE_PX = 36
ARENA = 6.0  # the arena is [-ARENA, ARENA]^2
PX_PER_UNIT = SIZE_PX / (2 * ARENA)
AGENT_RADIUS = 1.0
COLOURS: dict[str, tuple[int, int, int]] = {
    "red": (230, 40, 40),
    "green": (40, 200, 70),
    "blue": (50, 100, 240),
    "yellow": (240, 210, 40),
}
SHAPES = ("X", "square", "triangle", "diamond")
CORNERS: tuple[tuple[float, float], ...] = ((-5.0, 5.0), (5.0, 5.0), (-5.0, -5.0), (5.0, -5.0))
OBJ_PX = 6  # objects are 6x6 pixel glyphs centred on their corner


def _glyph(shape: str) -> np.ndarray:
    """bool (6, 6) mask of a shape, rows top to bottom."""
    c = np.arange(OBJ_PX) + 0.5 - OBJ_PX / 2  # pixel centres in [-2.5, 2.5]
    v, u = np.meshgrid(c, c, indexing="ij")  # v: down, u: right
    if shape == "X":
        return np.abs(np.abs(u) - np.abs(v)) <= 1.0
    if shape == "square":
        return np.ones((OBJ_PX, OBJ_PX), bool)
    if shape == "triangle":
        return np.abs(u) <= (v + 3.0) / 2.0
    if shape == "diamond":
        return np.abs(u) + np.abs(v) <= 3.0
    raise ValueError(shape)


def to_px(x: float, y: float) -> tuple[float, float]:
    """World (x, y) -> continuous pixel (col, row); row 0 is the top (y = +6)."""
    return (x + ARENA) * PX_PER_UNIT, (ARENA - y) * PX_PER_UNIT


def _layer_table() -> tuple[np.ndarray, np.ndarray]:
    """Every (corner, shape, colour) glyph as a full-frame mask and RGB layer.

    Returns masks bool (N, 36, 36) and colours uint8 (N, 3) with N = corners*shapes*colours,
    indexed by layer_index().
    """
    masks = np.zeros((len(CORNERS), len(SHAPES), SIZE_PX, SIZE_PX), bool)
    for i, (x, y) in enumerate(CORNERS):
        col, row = to_px(x, y)
        r0, c0 = int(row) - OBJ_PX // 2, int(col) - OBJ_PX // 2
        for j, shape in enumerate(SHAPES):
            masks[i, j, r0 : r0 + OBJ_PX, c0 : c0 + OBJ_PX] = _glyph(shape)
    return masks.reshape(-1, SIZE_PX, SIZE_PX), np.array(list(COLOURS.values()), np.uint8)


_MASKS, _RGB = _layer_table()  # (corners*shapes, 36, 36), (colours, 3)
_CENTRES = (np.arange(SIZE_PX) + 0.5) / PX_PER_UNIT - ARENA  # pixel centres in world units


def corner_index(pos: tuple[float, ...]) -> int:
    key = (float(pos[0]), float(pos[1]))
    if key not in CORNERS:
        raise ValueError(f"nav2d objects sit on corners {CORNERS}, not at {key}")
    return CORNERS.index(key)


OBJECT_REACH = ARENA - OBJ_PX / 2 / PX_PER_UNIT  # an object's centre within [-5, 5]^2: whole


def object_mask(pos: tuple[float, ...], shape: str) -> np.ndarray:
    """bool (36, 36): the glyph of `shape` centred on `pos`. On a corner, the table's mask;
    elsewhere (a scene parameter moved it, World.scene_parameters) the glyph's top-left pixel
    is the one its centre falls in less 3, as on the corners, so positions within a third of a
    unit draw alike. A centre outside [-OBJECT_REACH, OBJECT_REACH]^2 is refused."""
    x, y = float(pos[0]), float(pos[1])
    if (x, y) in CORNERS:
        return _MASKS[CORNERS.index((x, y)) * len(SHAPES) + SHAPES.index(shape)]
    if not (abs(x) <= OBJECT_REACH and abs(y) <= OBJECT_REACH):
        raise ValueError(f"a nav2d object's centre lies in [-5, 5]^2, not at {(x, y)}")
    col, row = to_px(x, y)
    return _mask_at(int(np.floor(row)) - OBJ_PX // 2, int(np.floor(col)) - OBJ_PX // 2, shape)


@functools.lru_cache(maxsize=4096)
def _mask_at(r0: int, c0: int, shape: str) -> np.ndarray:
    mask = np.zeros((SIZE_PX, SIZE_PX), bool)
    mask[r0 : r0 + OBJ_PX, c0 : c0 + OBJ_PX] = _glyph(shape)
    mask.flags.writeable = False
    return mask


def render_objects(masks: list[np.ndarray], colours: list[int]) -> np.ndarray:
    """The objects of one scene, masks bool (36, 36) each, drawn in slot order on black ->
    uint8 (36, 36, 3)."""
    out = np.zeros((SIZE_PX, SIZE_PX, 3), np.uint8)
    for m, c in zip(masks, colours, strict=True):
        out[m] = _RGB[c]
    return out


def draw_agents(layers: np.ndarray, agent_xy: np.ndarray) -> np.ndarray:
    """White agent discs over object layers: (B, 36, 36, 3) uint8, (B, 2) -> (B, 36, 36, 3).
    Frames whose agents stand in one place share one disc (a search's candidates start
    together)."""
    out = layers.copy()
    frames: dict[tuple[float, float], list[int]] = {}  # agent's place -> frames
    for b, (x, y) in enumerate(agent_xy.tolist()):
        frames.setdefault((x, y), []).append(b)
    for (x, y), rows in frames.items():
        r, c = disc_at(x, y)  # (N,), (N,)
        out[np.asarray(rows)[:, None], r[None], c[None]] = 255
    return out


@functools.lru_cache(maxsize=4096)
def disc_at(x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) int of the pixels whose centres lie within the agent's radius of (x, y)."""
    dx = _CENTRES[None, :] - x  # (1, 36)
    dy = _CENTRES[::-1][:, None] - y  # (36, 1)
    return np.nonzero(dx**2 + dy**2 <= AGENT_RADIUS**2)
