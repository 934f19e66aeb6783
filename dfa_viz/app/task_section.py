"""The page's "1 · Task" section: which world, shift and seed to load, and a box to list a world
by name ("minigrid:<EnvId>", "fetch:<EnvId>", ...) beside the registered ones."""

from __future__ import annotations

import threading

import viser

from dfa_viz.app.controls import SEED, Checked, one_of
from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View
from sim import get_world

NO_SHIFTS = "none: load a demonstration with dfa run --demo"


def shifts_of(world: str) -> tuple[str, ...]:
    """The shifts a world's test tasks come in (a world without them: one placeholder)."""
    return get_world(world).shifts or (NO_SHIFTS,)


def default_shift(shifts: tuple[str, ...]) -> str:
    return "distractor_ti" if "distractor_ti" in shifts else shifts[0]


class TaskSection:
    """The controls of the Task folder; `guard` wraps a button's action as the page does."""

    def __init__(self, client: viser.ClientHandle, state: LoopState, guard) -> None:
        self.client, self.state = client, state
        self._lock = threading.RLock()
        self._task_shown: int | None = None
        gui = client.gui
        with gui.add_folder("1 · Task"):
            world = gui.add_dropdown("world", state.worlds, initial_value=state.world_name)
            self.world = Checked(
                world,
                one_of(lambda: state.worlds),
                client,
                # the shifts on offer are the chosen world's own
                on_change=lambda _: self.offer_shifts(self.world.value),
            )
            self._shifts = shifts_of(state.world_name)  # the shifts offered now
            shift = gui.add_dropdown(
                "shift", self._shifts, initial_value=default_shift(self._shifts)
            )
            self.shift = Checked(shift, one_of(lambda: self._shifts), client)
            self.seed = Checked(gui.add_number("seed", 0, min=0, step=1), SEED, client)
            # disabled until their callbacks are attached (on_change enables them): a click
            # on a loaded machine while the page is still being built would be dropped
            self.load = gui.add_button("Load task", icon=viser.Icon.PLAYER_PLAY, disabled=True)
            self.next = gui.add_button(
                "Next task", icon=viser.Icon.PLAYER_TRACK_NEXT, disabled=True
            )
            prefixes = ", ".join(f"{p}:…" for p in state.offers.prefixes)
            self.typed = gui.add_text("another world", "", hint=f"a world by name: {prefixes}")
            self.add = gui.add_button("List this world", icon=viser.Icon.PLUS, disabled=True)
        self.load.on_click(
            guard(lambda _: state.pick(self.world.value, self.shift.value, self.seed.value))
        )
        self.next.on_click(guard(lambda _: state.next_task()))
        self.add.on_click(guard(self._list_typed))

    def _list_typed(self, _event) -> None:
        """List the typed world (refused in one line if no prefix builds it) and choose it."""
        name = str(self.typed.value).strip()
        self.state.offer_world(name)
        self.world.handle.options = self.state.worlds
        self.world.set(name)
        self.offer_shifts(name)

    def offer_shifts(self, world: str) -> None:
        shifts = shifts_of(world)
        with self._lock:
            if self._shifts != shifts:
                self._shifts = shifts  # first: the dropdown may take its first option at once
                self.shift.handle.options = shifts

    def draw(self, view: View) -> None:
        """Show what is loaded (maybe by another tab) and what may be pressed now."""
        run, busy = view.record, view.job is not None
        if tuple(self.world.handle.options) != self.state.worlds:  # another tab listed one
            self.world.handle.options = self.state.worlds
        if run is not None and id(run.task) != self._task_shown:
            self._task_shown = id(run.task)
            self.world.set(run.world)
            self.offer_shifts(run.world)
            if run.shift in self._shifts:  # not a failure the sweep found
                self.shift.set(run.shift)
            self.seed.set(run.seed)
        pickable = get_world(self.world.value).benchmark  # a world with test tasks to load
        for b in (self.load, self.next):
            b.disabled = busy or not pickable
        self.add.disabled = busy
