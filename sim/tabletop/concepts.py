"""The tabletop's concept space: the object to move, the goal to put it on and two optional
distractors (kind "distractor"), each a shape (29, sim.tabletop.catalogue) and a colour (the
configured appearances: 17 plain colours and textures, 81 by default)."""

from __future__ import annotations

from collections.abc import Sequence

from sim.core import Concept, ConceptSpace, Slot
from sim.tabletop.catalogue import SHAPES

DISTRACTORS = ("distractor0", "distractor1")


def space(colours: Sequence[str]) -> ConceptSpace:
    """Phi's codomain: every slot offers all 29 shapes and the configured colours."""
    shape, colour = Concept("shape", SHAPES), Concept("colour", tuple(colours))
    return ConceptSpace(
        (
            Slot("object", (shape, colour)),
            Slot("goal", (shape, colour)),
            *(Slot(d, (shape, colour), optional=True, kind="distractor") for d in DISTRACTORS),
        )
    )
