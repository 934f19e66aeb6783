"""Scenes: frozen values describing the objects and the agent of one world state."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from sim.core.errors import UserError


@dataclass(frozen=True)
class Obj:
    """One object slot of a scene.

    values: (concept, instantiation) pairs in the slot's concept order.
    pos: world-specific position (e.g. (x, y) in arena units); not part of Phi.
    An absent object keeps its values and pos: that is the appearance it takes when added.
    """

    slot: str
    present: bool
    values: tuple[tuple[str, str], ...]
    pos: tuple[float, ...]

    def value(self, concept: str) -> str:
        for name, v in self.values:
            if name == concept:
                return v
        raise UserError(
            f"slot {self.slot!r} has no concept {concept!r}; it has: "
            + ", ".join(n for n, _ in self.values)
        )

    def with_value(self, concept: str, value: str) -> Obj:
        self.value(concept)  # raises on an unknown concept
        values = tuple((n, value if n == concept else v) for n, v in self.values)
        return Obj(self.slot, self.present, values, self.pos)


@dataclass(frozen=True)
class Scene:
    """A world state: its objects in slot order and the agent's state.

    agent: world-specific numbers (nav2d: (x, y, t); doorkey: (col, row, dir, carrying, door, t)
    with minigrid's door codes; tabletop: (steps,)). Scenes are hashable values; `apply` makes
    edited copies.
    """

    world: str
    objects: tuple[Obj, ...]
    agent: tuple[float, ...] = ()

    def is_finite(self) -> bool:
        """True when every number of the scene (agent state, object positions) is finite."""
        return all(math.isfinite(v) for v in self.agent) and all(
            math.isfinite(v) for o in self.objects for v in o.pos
        )

    def obj(self, slot: str) -> Obj:
        for o in self.objects:
            if o.slot == slot:
                return o
        raise UserError(
            f"unknown slot {slot!r}; accepted: {', '.join(o.slot for o in self.objects)}"
        )

    def with_obj(self, obj: Obj) -> Scene:
        self.obj(obj.slot)
        objects = tuple(obj if o.slot == obj.slot else o for o in self.objects)
        return Scene(self.world, objects, self.agent)

    def to_dict(self) -> dict[str, Any]:
        return {
            "world": self.world,
            "agent": list(self.agent),
            "objects": [
                {
                    "slot": o.slot,
                    "present": o.present,
                    "values": dict(o.values),
                    "pos": list(o.pos),
                }
                for o in self.objects
            ],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Scene:
        try:
            objects = tuple(
                Obj(
                    str(o["slot"]),
                    bool(o["present"]),
                    tuple((str(k), str(v)) for k, v in o["values"].items()),
                    tuple(float(x) for x in o["pos"]),
                )
                for o in d["objects"]
            )
            return cls(str(d["world"]), objects, tuple(float(x) for x in d["agent"]))
        except (KeyError, TypeError, AttributeError, ValueError) as e:
            raise UserError(
                f"malformed scene ({type(e).__name__}: {e}); expected keys world, agent, "
                "objects[slot, present, values, pos]"
            ) from None

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)
