"""corridor: a complete small world, the example of docs/bring-your-own.md.

A white agent walks a corridor of seven cells to a coloured flag; a coloured box may stand in
one of the cells it walks past. Register it and every tool of dfa works on it:

    from sim import register_world
    register_world("corridor", "corridor:CorridorWorld")   # or a "dfa.worlds" entry point

Concepts  flag: colour (red, green, blue); box: presence, colour (red, green, blue).
Actions   3 discrete: 0 stay, 1 right, 2 left; 10 steps.
Shifts    none: a plain World is diagnosed from a demonstration the user gives (`--demo`).
Success   on the flag's cell after the last step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim.core import Concept, ConceptSpace, Key, Obj, Scene, Slot, Task, Trajectory, World

CELLS, CELL_PX = 7, 8  # the frame is one row of cells: 8 x 56 pixels
COLOURS = {"red": (230, 40, 40), "green": (40, 200, 70), "blue": (50, 100, 240)}
COLOUR = Concept("colour", tuple(COLOURS))
SPACE = ConceptSpace((Slot("flag", (COLOUR,)), Slot("box", (COLOUR,), optional=True)))


class CorridorWorld(World):
    """Scene: flag and box at (cell,); agent (cell, t)."""

    name = "corridor"
    space = SPACE
    horizon = 10
    obs_shape = (CELL_PX, CELLS * CELL_PX, 3)
    discrete = True
    action_dim = 3
    lossless_frames = True
    demo_input = "keys"
    keys = (Key("stay", "S", 0), Key("right", "arrowright", 1), Key("left", "arrowleft", 2))

    # -- what a world must give ---------------------------------------------------------------
    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, 8, 56, 3): the flag a full cell, the box a smaller square, the agent a
        white bar across its cell."""
        out = np.zeros((len(scenes), *self.obs_shape), np.uint8)
        for b, s in enumerate(scenes):
            for o in s.objects:
                if o.present:
                    x = int(o.pos[0]) * CELL_PX
                    inset = 0 if o.slot == "flag" else 2
                    out[b, inset : CELL_PX - inset, x + inset : x + CELL_PX - inset] = COLOURS[
                        o.value("colour")
                    ]
            x = int(s.agent[0]) * CELL_PX
            out[b, 3:5, x : x + CELL_PX] = 255
        return out

    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        actions = np.asarray(actions)
        assert actions.shape == (len(scenes),), f"actions must be (B,) ints, got {actions.shape}"
        out = []
        for s, a in zip(scenes, actions.tolist(), strict=True):
            if self.done(s):
                out.append(s)
                continue
            cell = min(max(int(s.agent[0]) + (1 if a == 1 else -1 if a == 2 else 0), 0), CELLS - 1)
            out.append(Scene(s.world, s.objects, (float(cell), s.agent[1] + 1)))
        return out

    def done(self, scene: Scene) -> bool:
        return scene.agent[1] >= self.horizon

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        return scenes[-1].agent[0] == scenes[-1].obj("flag").pos[0]

    def sample_scene(self, seed: int) -> Scene:
        """The flag on the last cell (its colour by the seed), the box absent."""
        colour = COLOUR.values[seed % len(COLOUR.values)]
        return Scene(
            self.name,
            (
                Obj("flag", True, (("colour", colour),), (float(CELLS - 1),)),
                Obj("box", False, (("colour", "blue"),), (3.0,)),
            ),
            (0.0, 0.0),
        )

    # -- optional: where a variant may add the box without blocking the demonstration ----------
    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        flag = int(task.scene.obj("flag").pos[0])
        return [(float(c),) for c in range(1, CELLS) if c != flag]
