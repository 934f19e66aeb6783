"""A Scene held in a MiniGrid environment, and read back from it.

A scene's layout (walls and what the environment's generator placed) is the environment reset
with a layout seed. Each layout has one environment instance (a bounded cache), reset once; a
scene is restored by setting the attributes of that layout's own objects and putting them on
their cells, so an environment that keeps references to its objects (Unlock checks its door)
still sees them, and MiniGrid's own `step` and renderer do the rest.

    Obj.pos  (col, row, state): the cell, or (-1, -1) while carried; state is the door's
             (0 open, 1 closed, 2 locked, MiniGrid's codes), 0 for other objects
    agent    (layout, col, row, dir, carried, step, won, done): the layout seed; the agent's
             cell and direction (MiniGrid's agent_dir); the index in the concept space of the
             slot it carries (-1: none); steps taken; 1.0 once the environment's reward was
             positive; 1.0 once the episode ended
"""

from __future__ import annotations

import contextlib
import sys
import threading
from collections import OrderedDict
from collections.abc import Callable

from minigrid.core.world_object import Ball, Box, Door, Goal, Key, Lava, WorldObj

from sim.core import ConceptSpace, Obj, Scene

MAKE = {"key": Key, "door": Door, "ball": Ball, "box": Box, "goal": Goal, "lava": Lava}
AGENT_FIELDS = ("layout", "col", "row", "dir", "carried", "step", "won", "done")
CACHED_LAYOUTS = 64


def _new(kind: str) -> WorldObj:
    if kind in ("box",):
        return Box("grey")
    return MAKE[kind]() if kind in ("goal", "lava") else MAKE[kind]("grey")


def _cell(env, inst: WorldObj) -> tuple[int, int] | None:
    """The cell `inst` stands on in the grid, or None (carried, removed, or never placed):
    MiniGrid keeps an object's cell in cur_pos, and the grid tells whether it is still there."""
    pos = inst.cur_pos
    if pos is None:
        return None
    i, j = int(pos[0]), int(pos[1])
    if 0 <= i < env.width and 0 <= j < env.height and env.grid.get(i, j) is inst:
        return (i, j)
    return None


def door_state(obj: WorldObj) -> int:
    if obj.type != "door":
        return 0
    return 0 if obj.is_open else (2 if obj.is_locked else 1)


def reset(env, seed: int) -> None:
    """env.reset(seed=seed), whatever it prints going to stderr: BabyAI levels print their
    rejected draws, and stdout is where `dfa run --json` writes its answer."""
    with contextlib.redirect_stdout(sys.stderr):
        env.reset(seed=int(seed))


def free_cells(env) -> list[tuple[int, int]]:
    """The empty floor cells the agent can get to, in row-major order: those joined to its
    cell by cells that hold anything but a wall (doors and objects can be opened or moved), off
    the grid's border (MultiRoom leaves empty cells outside its rooms)."""
    start = tuple(int(v) for v in env.agent_pos)
    seen, todo = {start}, [start]
    while todo:
        i, j = todo.pop()
        for nxt in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
            if nxt in seen or not (0 < nxt[0] < env.width - 1 and 0 < nxt[1] < env.height - 1):
                continue
            cell = env.grid.get(*nxt)
            if cell is None or cell.type != "wall":
                seen.add(nxt)
                todo.append(nxt)
    return sorted(
        ((i, j) for i, j in seen if env.grid.get(i, j) is None and (i, j) != start),
        key=lambda c: (c[1], c[0]),
    )


def _follow(env) -> None:
    """A BabyAI instruction's verifier set to the restored scene: where its objects are now,
    and what the agent carried before the step to come (what a Pickup or PutNext compares
    against); everything else it holds was fixed when the layout was made."""
    instrs = getattr(env, "instrs", None)
    if instrs is None:
        return
    env.update_objs_poss()
    if hasattr(instrs, "preCarrying"):
        instrs.preCarrying = env.carrying


def sequenced(env, seeds) -> bool:
    """True when env's instruction (BabyAI) is a sequence (before, after, and) on any layout
    of `seeds`: it keeps which part is done, which no scene holds."""
    from minigrid.envs.babyai.core.verifier import SeqInstr

    for seed in seeds:
        reset(env, seed)
        if isinstance(getattr(env, "instrs", None), SeqInstr):
            return True
        if getattr(env, "instrs", None) is None:
            return False  # not a BabyAI level: nothing to look at on other layouts
    return False


def _unobserved() -> dict:
    """What a layout's environment gives as the observation of a step: nothing. MiniGrid's
    step ends by drawing the agent's view (gen_obs: most of a step's time, and the expert's
    plans take thousands of steps), and no scene is read from it; frames are drawn apart."""
    return {}


class Layouts:
    """One environment per layout seed, with its objects as the slots of the concept space."""

    def __init__(self, make_env: Callable[[], object], space: ConceptSpace, world: str) -> None:
        self.make_env, self.space, self.world = make_env, space, world
        self.slot_names = tuple(s.name for s in space.slots)
        self._envs: OrderedDict[int, tuple[object, dict[str, WorldObj], Scene]] = OrderedDict()
        self._lock = threading.RLock()

    def get(self, layout: int) -> tuple[object, dict[str, WorldObj], Scene]:
        """(environment, slot -> its object, the layout's initial scene)."""
        with self._lock:
            if layout in self._envs:
                self._envs.move_to_end(layout)
                return self._envs[layout]
            env = self.make_env()
            reset(env, layout)
            env.gen_obs = _unobserved  # its steps are read for their state (Layouts.read) only
            objs: dict[str, WorldObj] = {}
            seen: dict[str, int] = {}
            for j in range(env.height):  # row-major: the slots' order on every layout
                for i in range(env.width):
                    o = env.grid.get(i, j)
                    if o is None or f"{o.type}0" not in self.slot_names:
                        continue
                    k = seen.get(o.type, 0)
                    seen[o.type] = k + 1
                    o.cur_pos = (i, j)
                    objs[f"{o.type}{k}"] = o
            free = self._free_cells(env)
            latent = {}
            for s in self.space.slots:  # slots this layout lacks wait on a free cell
                if s.name not in objs:
                    objs[s.name] = _new(s.kind)
                    latent[s.name] = free.pop(0) if free else (0, 0)
            scene = self.read(env, objs, layout=layout, won=0.0, done=0.0, latent=latent)
            self._envs[layout] = (env, objs, scene)
            if len(self._envs) > CACHED_LAYOUTS:
                self._envs.popitem(last=False)
            return self._envs[layout]

    @staticmethod
    def _free_cells(env) -> list[tuple[int, int]]:
        return free_cells(env)

    def restore(self, scene: Scene):
        """The environment of the scene's layout, set to the scene (holding the lock is the
        caller's: `with layouts.lock:`)."""
        env, objs, _ = self.get(int(scene.agent[0]))
        for inst in objs.values():  # take every slot object off the grid
            at = _cell(env, inst)
            if at is not None:
                env.grid.set(*at, None)
        env.carrying = None
        for o in scene.objects:
            if not o.present:
                continue
            inst = objs[o.slot]
            if len(self.space.slot(o.slot).concepts[0].values) > 1:  # lava's one colour stays
                inst.color = o.value("colour")
            if inst.type == "door":
                inst.is_open, inst.is_locked = o.pos[2] == 0, o.pos[2] == 2
            col, row = int(o.pos[0]), int(o.pos[1])
            if col < 0:
                env.carrying = inst
                inst.cur_pos = (-1, -1)
            else:
                env.grid.set(col, row, inst)
                inst.cur_pos = (col, row)
        _, col, row, direction, _, step, _, _ = scene.agent
        env.agent_pos, env.agent_dir, env.step_count = (
            (int(col), int(row)),
            int(direction),
            int(step),
        )
        _follow(env)
        return env, objs

    @property
    def lock(self):
        return self._lock

    def read(
        self, env, objs, *, layout: int, won: float, done: float, latent=None, before=None
    ) -> Scene:
        """The scene the environment is in. A slot absent from the grid keeps its look and
        place from `before` (the scene stepped from), or waits on its `latent` cell: never
        from what an earlier scene left in the shared objects."""
        carried = -1
        objects = []
        for k, s in enumerate(self.space.slots):
            inst = objs[s.name]
            choices = s.concepts[0].values
            values = (("colour", inst.color if len(choices) > 1 else choices[0]),)
            if env.carrying is inst:
                carried = k
                objects.append(Obj(s.name, True, values, (-1.0, -1.0, 0.0)))
            elif (at := _cell(env, inst)) is not None:
                i, j = at
                objects.append(
                    Obj(s.name, True, values, (float(i), float(j), float(door_state(inst))))
                )
            elif before is not None:
                was = before.obj(s.name)
                objects.append(Obj(s.name, False, was.values, was.pos))
            else:
                cell = latent[s.name]
                objects.append(
                    Obj(
                        s.name,
                        False,
                        values,
                        (float(cell[0]), float(cell[1]), float(door_state(inst))),
                    )
                )
        col, row = (int(v) for v in env.agent_pos)
        agent = (float(layout), float(col), float(row), float(env.agent_dir), float(carried),
                 float(env.step_count), float(won), float(done))  # fmt: skip
        return Scene(self.world, tuple(objects), agent)
