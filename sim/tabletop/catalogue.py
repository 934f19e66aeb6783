"""The names of the 29 VIMA shapes and which of them are manipulated objects or goals (no
geometry here: importing this is cheap)."""

SHAPES: tuple[str, ...] = (
    "letter A",
    "letter E",
    "letter G",
    "letter M",
    "letter R",
    "letter T",
    "letter V",
    "cross",
    "diamond",
    "triangle",
    "flower",
    "heart",
    "hexagon",
    "pentagon",
    "star",
    "ring",
    "round",
    "L-shaped block",
    "block",
    "shorter block",
    "small block",
    "line",
    "container",
    "square",
    "three-sided rectangle",
    "bowl",
    "pallet",
    "frame",
    "pan",
)
# The shapes a manipulated object takes: the first 19 (letters .. L-shaped block, and block).
MANIPULATED: tuple[str, ...] = SHAPES[:19]
GOALS: tuple[str, ...] = ("bowl", "frame", "square", "container", "pallet", "pan")
