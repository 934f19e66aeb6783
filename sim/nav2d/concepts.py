"""nav2d's concept space: a goal and an optional distractor, each a colour and a shape."""

from __future__ import annotations

from sim.core import Concept, ConceptSpace, Slot
from sim.nav2d import render as R

COLOUR = Concept("colour", tuple(R.COLOURS))
SHAPE = Concept("shape", R.SHAPES)
SPACE = ConceptSpace(
    (
        Slot("goal", (COLOUR, SHAPE)),
        Slot("distractor", (COLOUR, SHAPE), optional=True),
    )
)
