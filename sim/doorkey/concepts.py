"""DoorKey's concept space: the key, the door and the goal, each a colour, and three optional
lava tiles, orange or pink (lava0..lava2: one kind, "lava")."""

from __future__ import annotations

from sim.core import Concept, ConceptSpace, Slot

OBJ_COLOURS = ("red", "green", "blue", "yellow")
LAVA_COLOURS = ("orange", "pink")
OBJ_SLOTS = ("key", "door", "goal")
LAVA_SLOTS = ("lava0", "lava1", "lava2")
COLOUR = Concept("colour", OBJ_COLOURS)
LAVA_COLOUR = Concept("colour", LAVA_COLOURS)
SPACE = ConceptSpace(
    (
        Slot("key", (COLOUR,)),
        Slot("door", (COLOUR,)),
        Slot("goal", (COLOUR,)),
        *(Slot(s, (LAVA_COLOUR,), optional=True, kind="lava") for s in LAVA_SLOTS),
    )
)
SLOT_NAMES = OBJ_SLOTS + LAVA_SLOTS
