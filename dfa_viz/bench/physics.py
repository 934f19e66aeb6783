"""The physics bound of a sweep: the world's own steps and renders that the sweep made (the
very batches, recorded in one run of it in this process: its policy's rollouts, the expert's
demonstrations and, where the policy failed, the expert's check), timed alone.

On the tabletop a rollout is one pick-and-place simulated by MuJoCo, so its sweep's time goes
to physics, not to the policy: no sweep that steps the scenes it judges can take less time than
those steps and renders, whatever batches its forward passes see. Its ratio to the larger of
this bound and the forward-pass bound is what the sweep adds (bookkeeping, the policy's passes
beside the physics)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from dfa_viz.bench.timing import best_of
from sim.core import Scene, World


@dataclass
class Calls:
    """The world's step_batch and render_batch calls, in order, with what each was given."""

    steps: list[tuple[list[Scene], np.ndarray]] = field(default_factory=list)
    renders: list[list[Scene]] = field(default_factory=list)

    @property
    def stepped(self) -> int:
        """Scenes stepped in all."""
        return sum(len(s) for s, _ in self.steps)

    @property
    def rendered(self) -> int:
        """Frames rendered in all."""
        return sum(len(s) for s in self.renders)


@contextlib.contextmanager
def recorded(world: World) -> Iterator[Calls]:
    """Within the block, every step_batch and render_batch of `world` (this instance, in this
    process, calls the world makes itself included) is recorded as well as run."""
    calls = Calls()
    step, render = world.step_batch, world.render_batch

    def step_batch(scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        calls.steps.append((list(scenes), np.array(actions)))
        return step(scenes, actions)

    def render_batch(scenes: Sequence[Scene]) -> np.ndarray:
        calls.renders.append(list(scenes))
        return render(scenes)

    world.step_batch = step_batch  # type: ignore[method-assign]
    world.render_batch = render_batch  # type: ignore[method-assign]
    try:
        yield calls
    finally:
        del world.step_batch  # the class's own methods again
        del world.render_batch


def physics_bound_s(world: World, calls: Calls, repeats: int) -> float:
    """Seconds the recorded steps and renders take, replayed alone in their order (the best
    of `repeats`)."""

    def run() -> None:
        for scenes, actions in calls.steps:
            world.step_batch(scenes, actions)
        for scenes in calls.renders:
            world.render_batch(scenes)

    return best_of(run, repeats)[0]


def record_sweep(world: World, run: Callable[[], object]) -> Calls:
    """The steps and renders of one run of `run` (a sweep of `world` in this process)."""
    with recorded(world) as calls:
        run()
    return calls


def bench_physics(name: str, *, tasks: int = 100, repeats: int = 1) -> dict:
    """The physics bound of `dfa sweep` over `tasks` training tasks: one run of the sweep in
    this process (one torch thread, as a worker) recorded, then its steps and renders timed
    alone, the best of `repeats`."""
    from dfa_viz.backends import one_torch_thread
    from dfa_viz.checked_policy import checked_policy
    from search.sweep import sweep, sweep_tasks
    from sim import get_world

    world = get_world(name)
    policy = checked_policy(name, None)
    todo = sweep_tasks(world, tasks)
    with one_torch_thread():
        calls = record_sweep(world, lambda: sweep(world, policy, todo))
    return {
        "physics_s": physics_bound_s(world, calls, repeats),
        "stepped": calls.stepped,
        "rendered": calls.rendered,
    }
