"""grid_reacher: a plain gymnasium environment made a world in a few lines (sim.gymenv), the
example of docs/bring-your-own.md.

The environment (GridReacher, registered as "dfa_examples/GridReacher-v0") knows nothing of dfa:
a white agent starts in the middle of a 9x9 grid and walks to a coloured target on one of the
four corners; a hollow coloured square, the marker, may stand on another corner. Frames are
36x36 RGB, drawn with numpy; 5 actions (stay, up, down, left, right); reward 1 on reaching the
target, which ends the episode; 10 steps.

The world needs the state as numbers and back, and a table of concept edits:

    dfa check-world grid_reacher:reacher      # with docs/examples on PYTHONPATH
    dfa run --world grid_reacher:reacher --shift object_ti --seed 0
"""

from __future__ import annotations

import gymnasium
import numpy as np

from sim.core import Key
from sim.gymenv import ConceptEdit, GymWorld

SIZE, CELL = 9, 4  # cells per side, pixels per cell: 36x36 frames
CORNERS, MIDDLE = ((1, 1), (7, 1), (1, 7), (7, 7)), (4, 4)
COLOURS = {"red": (255, 0, 0), "green": (0, 255, 0), "blue": (0, 0, 255), "yellow": (255, 255, 0)}
NAMES = tuple(COLOURS)
MOVES = ((0, 0), (0, -1), (0, 1), (-1, 0), (1, 0))  # stay, up, down, left, right
HOTKEYS = {
    "stay": "S",
    "up": "arrowup",
    "down": "arrowdown",
    "left": "arrowleft",
    "right": "arrowright",
}
KEYS = tuple(Key(name, hotkey, i) for i, (name, hotkey) in enumerate(HOTKEYS.items()))
SHOWN = ("absent", "present")  # the marker's presence, as the state holds it (0, 1)
# the state: agent x, y; target x, y, colour; marker present, x, y, colour
AX, AY, TX, TY, TC, MP, MX, MY, MC = range(9)


class GridReacher(gymnasium.Env):
    """Reach the coloured target; see the module docstring. `state` is float64 (9,)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(self, render_mode: str | None = "rgb_array") -> None:
        self.render_mode = render_mode
        self.observation_space = gymnasium.spaces.Box(
            0, 255, (SIZE * CELL, SIZE * CELL, 3), np.uint8
        )
        self.action_space = gymnasium.spaces.Discrete(len(MOVES))
        self.state = np.zeros(9)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        t, m = self.np_random.choice(len(CORNERS), size=2, replace=False)
        self.state = np.array([*MIDDLE, *CORNERS[t], 0, 0, *CORNERS[m], 2], np.float64)
        return self.render(), {}

    def step(self, action):
        dx, dy = MOVES[int(action)]
        s = self.state
        s[AX], s[AY] = np.clip(s[AX] + dx, 0, SIZE - 1), np.clip(s[AY] + dy, 0, SIZE - 1)
        reached = bool(s[AX] == s[TX] and s[AY] == s[TY])
        return self.render(), float(reached), reached, False, {}

    def render(self) -> np.ndarray:
        s, img = self.state, np.zeros((SIZE * CELL, SIZE * CELL, 3), np.uint8)

        def cell(x, y):
            return img[int(y) * CELL : (int(y) + 1) * CELL, int(x) * CELL : (int(x) + 1) * CELL]

        cell(s[TX], s[TY])[:] = COLOURS[NAMES[int(s[TC])]]
        if s[MP]:
            ring = cell(s[MX], s[MY])
            ring[:], ring[1:-1, 1:-1] = COLOURS[NAMES[int(s[MC])]], 0
        cell(s[AX], s[AY])[1:-1, 1:-1] = 255
        return img


gymnasium.register("dfa_examples/GridReacher-v0", entry_point=GridReacher, max_episode_steps=10)


def set_value(index: int, names: tuple[str, ...]):
    """A concept edit: the state with state[index] = the value's position in `names`."""

    def apply(state: np.ndarray, value: str) -> np.ndarray:
        state[index] = names.index(value)
        return state

    return apply


def expert(state: np.ndarray) -> int:
    """Straight to the target, across then down; colours and the marker play no part."""
    dx, dy = np.sign(state[TX] - state[AX]), np.sign(state[TY] - state[AY])
    return MOVES.index((int(dx), 0) if dx else (0, int(dy)))


def reacher() -> GymWorld:
    """The world: the target red in training; the marker absent, blue when it appears."""
    blue_first = ("blue", *(n for n in NAMES if n != "blue"))
    return GymWorld(
        "gridreacher",
        env_id="dfa_examples/GridReacher-v0",
        get_state=lambda env: env.state.copy(),
        set_state=lambda env, state: setattr(env, "state", state.copy()),
        concepts=(
            ConceptEdit("target.colour", NAMES, set_value(TC, NAMES)),
            ConceptEdit("marker.presence", SHOWN, set_value(MP, SHOWN)),
            ConceptEdit("marker.colour", blue_first, set_value(MC, NAMES)),
        ),
        expert=expert,
        instruction="reach the target",
        keys=KEYS,
    )
