"""What a MiniGrid mission names, and so what the task's R' holds relevant.

A MiniGrid environment says what it wants in its mission string ("go to the green door",
"open the red door then the blue door", "put the grey key next to the green key", "pick up a
ball"). Every object the mission names, by its type (and colour, where it gives one), is part
of the task: its presence is task-relevant, and so is its colour when the mission says it. An
object of a named type that the mission's colour does not single out may take any colour but
the named ones (another door turned green would make "the green door" ambiguous). A goal's
presence is always relevant: reaching it is what the environment rewards.

Where a colour in the mission picks some of the objects of its type out of others that the
frames show alike, or where missions differ between layouts and name one of several objects on
the grid (the target is in the text), a policy that sees frames alone has to guess it:
`Mission.hidden` says so, and the world tells the user once (`MiniGridWorld.notes`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from minigrid.core.constants import COLOR_NAMES

from sim.core import PRESENCE, ConceptSpace, Scene

NOUNS = {
    "key": "key",
    "keys": "key",
    "door": "door",
    "doors": "door",
    "ball": "ball",
    "balls": "ball",
    "box": "box",
    "boxes": "box",
    "goal": "goal",
    "goals": "goal",
    "lava": "lava",
    "object": None,  # "the red object": an object of any type in that colour
    "objects": None,
    "room": "door",  # "the grey room": the room behind the grey door (LockedRoom)
}
COLOURED = ("key", "door", "ball", "box", "goal")


@dataclass(frozen=True)
class Named:
    """One object the mission names: its type (None: any type) and colour (None: any)."""

    kind: str | None
    colour: str | None

    def kinds(self) -> tuple[str, ...]:
        return COLOURED if self.kind is None else (self.kind,)


def named(text: str) -> tuple[Named, ...]:
    """The objects a mission names, in its order: each type word (key, door, ball, box, goal,
    lava; "object" and "room" only after a colour), with the colour word before it if any."""
    words = re.findall(r"[a-z]+", text.lower())
    out: list[Named] = []
    for i, word in enumerate(words):
        if word not in NOUNS:
            continue
        colour = words[i - 1] if i > 0 and words[i - 1] in COLOR_NAMES else None
        if (NOUNS[word] is None or word == "room") and colour is None:
            continue  # "the matching object", "traverse the rooms": nothing singled out
        named_ = Named(NOUNS[word], colour)
        if named_ not in out:
            out.append(named_)
    return tuple(out)


@dataclass(frozen=True)
class Mission:
    """A mission string and what it names."""

    text: str
    names: tuple[Named, ...]

    @classmethod
    def of(cls, text: str) -> Mission:
        return cls(str(text), named(str(text)))

    def banned(self, kind: str) -> tuple[str, ...]:
        """The colours the mission names for objects of `kind`: an object it does not name
        must not take them."""
        return tuple(
            c for c in COLOR_NAMES if any(n.colour == c and kind in n.kinds() for n in self.names)
        )

    def colours_for(self, kind: str) -> tuple[str, ...]:
        """The colours an object of `kind` that the mission does not name may take."""
        banned = set(self.banned(kind))
        return tuple(c for c in COLOR_NAMES if c not in banned)

    def names_any(self, kind: str) -> bool:
        """True when the mission names `kind` without a colour: any object of it would do, so
        adding one is not irrelevant."""
        return any(n.colour is None and n.kind == kind for n in self.names)

    def picked(self, space: ConceptSpace, scene: Scene, n: Named) -> list[str]:
        """The present slots of `scene` that `n` names."""
        return [
            o.slot
            for o in scene.objects
            if o.present
            and space.slot(o.slot).kind in n.kinds()
            and (n.colour is None or o.value("colour") == n.colour)
        ]

    def relevant(self, space: ConceptSpace, scene: Scene) -> frozenset[tuple[str, str]]:
        """(slot, concept) pairs of `scene` that the mission makes task-relevant: each named
        object's presence (and colour, when named), every goal's presence, and the presence
        of slots of a type named without a colour (one added there would count)."""
        out: set[tuple[str, str]] = set()
        for s in space.slots:
            goal = s.kind == "goal" and scene.obj(s.name).present
            if goal or (s.kind is not None and self.names_any(s.kind)):
                out.add((s.name, PRESENCE))
        for n in self.names:
            for slot in self.picked(space, scene, n):
                out.add((slot, PRESENCE))
                if n.colour is not None:
                    out.add((slot, "colour"))
        return frozenset(out)

    def hidden(self, space: ConceptSpace, scene: Scene, kinds: tuple[str, ...] = ()) -> bool:
        """True when the target is in the text, not in the frames: a colour in the mission
        picks some objects of its type out of others on the grid, or (`kinds`: the types that
        missions of other layouts name, when they differ) an object of one of those types is
        on the grid without being named."""
        picked: set[str] = set()
        for n in self.names:
            these = set(self.picked(space, scene, n))
            picked |= these
            of_kind = {
                o.slot for o in scene.objects if o.present and space.slot(o.slot).kind in n.kinds()
            }
            if n.colour is not None and these < of_kind:
                return True
        return any(
            o.present and space.slot(o.slot).kind in kinds and o.slot not in picked
            for o in scene.objects
        )
