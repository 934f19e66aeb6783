"""What the page offers, checked whoever calls: a tab can send any value. Each check returns the
value's world or raises a UserError saying what is accepted."""

from __future__ import annotations

from dataclasses import dataclass, replace

from sim import get_world, world_names
from sim.core import UserError, World, check_seed

SWEEP_TASKS = (1, 500)  # the Sweep tab's range of training tasks


@dataclass(frozen=True)
class Offers:
    worlds: tuple[str, ...]
    """The worlds the page lists: the registered ones, the session's own and those typed."""
    prefixes: tuple[str, ...] = ()
    """The registered prefixes ("minigrid", "fetch", ...): any "<prefix>:<rest>" may be typed."""

    @classmethod
    def for_session(cls, world: str) -> Offers:
        names = world_names()
        worlds = tuple(n for n in names if not n.endswith(":..."))
        prefixes = tuple(n.removesuffix(":...") for n in names if n.endswith(":..."))
        return cls(worlds if world in worlds else (*worlds, world), prefixes)

    def typed(self, name: str) -> Offers:
        """The offers with a world the user typed ("<prefix>:<rest>", built here to check it),
        listed from now on."""
        name = name.strip()
        head, _, rest = name.partition(":")
        if name not in self.worlds and (head not in self.prefixes or not rest):
            shown = ", ".join(f"{p}:<name>" for p in self.prefixes)
            raise UserError(f"no world {name!r} here; accepted: {shown}")
        get_world(name)  # an unknown <rest>: the world's own one line
        return self if name in self.worlds else replace(self, worlds=(*self.worlds, name))

    def world(self, name: str) -> World:
        """The world, if the page offers it (nothing is built for another)."""
        if name not in self.worlds:
            raise UserError(f"no world {name!r} here; accepted: {', '.join(self.worlds)}")
        return get_world(name)

    def task(self, world: str, shift: str, seed: int) -> World:
        """The world of a test task: one of the worlds, a shift of it, a seed from 0 to
        MAX_SEED."""
        w = self.world(world)
        if shift not in w.shifts:
            accepted = ", ".join(w.shifts) or "none (it has no test tasks)"
            raise UserError(f"{world} has no shift {shift!r}; accepted: {accepted}")
        check_seed(seed)
        return w

    def sweep(self, world: str, tasks: int) -> World:
        """The world of a sweep over `tasks` training tasks (SWEEP_TASKS)."""
        w = self.world(world)
        low, high = SWEEP_TASKS
        if isinstance(tasks, bool) or not isinstance(tasks, int) or not low <= tasks <= high:
            raise UserError(f"a sweep takes {low} to {high} tasks, not {tasks!r}")
        return w
