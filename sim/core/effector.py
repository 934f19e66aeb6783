"""Waypoints of a robot's end effector, clicked on a world's frames (World.demo_input
"effector"): the demonstration a person gives a closed-loop arm on the page."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Waypoint:
    """Where the end effector should go next, in the world's frame (metres)."""

    pos: tuple[float, float, float]
    grasp: str = ""
    """The slot the fingers close on here ("": none); they stay closed from then on."""
    on: str = ""
    """What the click that made it met, in words for the page ("the table", "the object");
    "": a point in the air (placed by a second click, in another view)."""
    ray: tuple[float, ...] = ()
    """(origin x, y, z, direction x, y, z) of the click in the first view that made it: a
    click on the same point in another view places it where the two rays meet."""
    replaces: bool = False
    """True: the waypoint before it, placed anew by a click in another view (not a new one)."""

    def describe(self) -> str:
        """This waypoint in a few words ("grasp the object", "over the table",
        "at 0.55 m")."""
        if self.grasp:
            return f"grasp the {self.grasp}"
        return f"over {self.on}" if self.on else f"at {self.pos[2]:.2f} m"
