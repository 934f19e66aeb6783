"""The concept space of a MiniGrid environment, read from its grids.

Every object on a grid is a slot of its type's kind (key0, door0, ball0, ball1, box0, goal0,
lava0, ...): as many slots of a type as the most any of the first SAMPLE_LAYOUTS layouts has.
Keys, doors, balls, boxes and goals have a colour over MiniGrid's six; lava's colour has one
value, orange, as MiniGrid always draws it (so that Phi still shows whether a lava tile is
there). Every slot is optional: an object can be removed, and an absent one is
added back on its cell. One extra ball per world, absent in every layout, is what a distractor
shift adds.
"""

from __future__ import annotations

from collections import Counter

from minigrid.core.constants import COLOR_NAMES

from sim.core import Concept, ConceptSpace, Slot
from sim.minigrid.state import reset

SAMPLE_LAYOUTS = 20
TYPES = ("key", "door", "ball", "box", "goal", "lava")  # the object types that become slots
COLOURED = ("key", "door", "ball", "box", "goal")
COLOUR = Concept("colour", tuple(COLOR_NAMES))
LAVA_COLOUR = Concept("colour", ("orange",))
DISTRACTOR = "ball"  # what a distractor shift adds


def count_objects(env, seeds) -> Counter:
    """The most objects of each type any of the layouts of `seeds` has."""
    most: Counter = Counter()
    for seed in seeds:
        reset(env, seed)
        here = Counter(o.type for o in env.grid.grid if o is not None and o.type in TYPES)
        for t, n in here.items():
            most[t] = max(most[t], n)
    return most


def space_for(counts: Counter) -> tuple[ConceptSpace, str]:
    """The concept space for these object counts, and the name of the distractor's slot."""
    slots = []
    for t in TYPES:
        concepts = (COLOUR,) if t in COLOURED else (LAVA_COLOUR,)
        n = counts.get(t, 0) + (1 if t == DISTRACTOR else 0)
        slots += [Slot(f"{t}{i}", concepts, optional=True, kind=t) for i in range(n)]
    distractor = f"{DISTRACTOR}{counts.get(DISTRACTOR, 0)}"
    return ConceptSpace(tuple(slots)), distractor
