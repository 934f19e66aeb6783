"""The 82 appearances of the VIMA set: 17 plain colours and 65 procedural textures (names only
and plain RGB here; the texture images are made by sim.tabletop.textures)."""

from __future__ import annotations

import colorsys

BASE_RGB: dict[str, tuple[int, int, int]] = {
    "blue": (78, 121, 167),
    "red": (255, 87, 89),
    "green": (89, 169, 79),
    "orange": (242, 142, 43),
    "yellow": (237, 201, 72),
    "purple": (176, 122, 161),
    "pink": (255, 157, 167),
    "cyan": (118, 183, 178),
    "olive": (128, 128, 0),
}


def darker(rgb: tuple[int, int, int], offset: float = 0.3) -> tuple[int, int, int]:
    """The "dark" variant: HSV value lowered by `offset` (as VIMA does)."""
    h, s, v = colorsys.rgb_to_hsv(*(c / 255 for c in rgb))
    r, g, b = colorsys.hsv_to_rgb(h, s, max(0.0, v - offset))
    return (round(r * 255), round(g * 255), round(b * 255))


PLAIN_RGB: dict[str, tuple[int, int, int]] = {
    **BASE_RGB,
    **{f"dark {n}": darker(c) for n, c in BASE_RGB.items() if n != "olive"},
}
NAMED_TEXTURES = (
    "brick",
    "tiles",
    "wooden",
    "granite",
    "plastic",
    "polka dot",
    "checkerboard",
    "tiger",
    "magma",
    "rainbow",
)
PATTERN_COLOURS = ("red", "yellow", "green", "blue", "purple")
COLOUR_PAIRS = tuple(
    (a, b) for i, a in enumerate(PATTERN_COLOURS) for b in PATTERN_COLOURS[i + 1 :]
)


def _combo(kind: str) -> tuple[str, ...]:
    return tuple(f"{dark}{a} and {b} {kind}" for a, b in COLOUR_PAIRS for dark in ("", "dark "))


TEXTURES: tuple[str, ...] = (
    *NAMED_TEXTURES,
    *_combo("stripe"),
    *_combo("polka dot"),
    *(f"{dark}{c} swirl" for c in PATTERN_COLOURS for dark in ("", "dark ")),
    *(f"{c} paisley" for c in PATTERN_COLOURS),
)
ALL_COLOURS: tuple[str, ...] = (*PLAIN_RGB, *TEXTURES)
# The default list leaves out granite: grey speckle is the one appearance that nearly
# vanishes against the grey table.
EXCLUDED_BY_DEFAULT = ("granite",)
DEFAULT_COLOURS: tuple[str, ...] = tuple(c for c in ALL_COLOURS if c not in EXCLUDED_BY_DEFAULT)
TABLE_RGB = (128, 128, 128)

assert len(PLAIN_RGB) == 17 and len(TEXTURES) == 65 and len(DEFAULT_COLOURS) == 81


def is_plain(name: str) -> bool:
    return name in PLAIN_RGB
