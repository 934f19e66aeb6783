"""A scripted expert for any MiniGrid environment: a breadth-first search over the scenes the
environment's own `step` reaches, to the shortest plan that earns a positive reward.

The search first tries plans that never drop anything (what most tasks need, and a small
search: objects then only move with the agent); only when there is none does it search with
every action, within MAX_EXPANDED scenes.

Plans are cached by scene without its step count, with the steps that were left when each was
found, and every scene along a plan keeps the rest of it, so a closed-loop demonstration searches
once. A scene the search cannot solve within the steps left (or within MAX_EXPANDED scenes) has
no plan, nor has it later with fewer steps left: the expert then takes the idle action without
searching again, and the task generator rejects such scenes.
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque

from sim.core import Scene

MAX_EXPANDED = 20_000
CACHED = 4096
DROP = 4  # MiniGrid's drop action


def _key(scene: Scene) -> Scene:
    """The scene without its step count: the search's notion of "the same state"."""
    a = scene.agent
    return Scene(scene.world, scene.objects, (*a[:5], 0.0, *a[6:]))


class Planner:
    def __init__(self, world) -> None:
        self.world = world
        # scene without its step count -> (plan or None, the steps that were left then)
        self._plans: OrderedDict[Scene, tuple[tuple[int, ...] | None, int]] = OrderedDict()
        self._lock = threading.Lock()

    def plan(self, scene: Scene, *, thorough: bool = True) -> tuple[int, ...] | None:
        """The shortest action sequence from `scene` to a positive reward, or None. Without
        `thorough`, only plans that drop nothing are looked for (a quick "no" for the task
        generator's draws)."""
        with self._lock:
            known = self._known(scene)
        if known is not None:
            return known[0]
        plan = self._search(scene, thorough)
        if plan is None and not thorough:
            return None  # not remembered: a thorough search may still find one
        with self._lock:
            self._remember(scene, plan)
            if plan:  # the rest of the plan from every scene along it
                s = scene
                for i, a in enumerate(plan[:-1]):
                    s = self.world.step_one(s, a)
                    self._remember(s, plan[i + 1 :])
        return plan

    def _left(self, scene: Scene) -> int:
        return self.world.horizon - int(scene.agent[5])

    def _known(self, scene: Scene) -> tuple[tuple[int, ...] | None] | None:
        """(plan,) where the cache settles `scene`: a plan that fits the steps left, or none
        found with at least as many steps left; else None (search)."""
        entry = self._plans.get(_key(scene))
        if entry is None:
            return None
        plan, left = entry
        if plan is None:
            return (None,) if left >= self._left(scene) else None
        return (plan,) if len(plan) <= self._left(scene) else None

    def _remember(self, scene: Scene, plan) -> None:
        key = _key(scene)
        self._plans[key] = (plan, self._left(scene))
        self._plans.move_to_end(key)
        while len(self._plans) > CACHED:
            self._plans.popitem(last=False)

    def _search(self, start: Scene, thorough: bool = True) -> tuple[int, ...] | None:
        w = self.world
        if w.done(start):
            return () if start.agent[6] > 0 else None
        keep = tuple(a for a in range(w.action_dim) if a != DROP)
        plan = self._bfs(start, keep)
        if plan is not None or not thorough or len(keep) == w.action_dim:
            return plan
        return self._bfs(start, None)

    def _bfs(self, start: Scene, actions: tuple[int, ...] | None) -> tuple[int, ...] | None:
        w = self.world
        actions = actions or tuple(range(w.action_dim))
        left = w.horizon - int(start.agent[5])
        parents: dict[Scene, tuple[Scene | None, int]] = {_key(start): (None, -1)}
        frontier = deque([(start, 0)])
        while frontier and len(parents) < MAX_EXPANDED:
            scene, depth = frontier.popleft()
            if depth >= left:
                continue
            for a in actions:
                nxt = w.step_one(scene, a)
                k = _key(nxt)
                if k in parents:
                    continue
                parents[k] = (_key(scene), a)
                if nxt.agent[6] > 0:  # rewarded: walk the parents back
                    actions, cur = [], k
                    while parents[cur][0] is not None:
                        prev, act = parents[cur]
                        actions.append(act)
                        cur = prev
                    return tuple(reversed(actions))
                if not w.done(nxt):
                    frontier.append((nxt, depth + 1))
        return None


def solvable(world, scene: Scene) -> bool:
    return world.planner.plan(scene) is not None
