"""The policies a page session diagnoses: each world's base policy, or the one `dfa serve
--policy` names for the world the page opens on, and each world's training demonstrations; made
once per process."""

from __future__ import annotations

import threading
from pathlib import Path

from policy import Policy, base_policy, training_demos
from policy.outside import chosen_policy
from sim.core import World


class Policies:
    """The policy diagnosed in each world and its training demonstrations, made once."""

    def __init__(
        self, *, spec: str | None = None, world: str | None = None, weights: Path | None = None
    ) -> None:
        self._lock = threading.Lock()
        self._policies: dict[str, Policy] = {}
        self._known: dict[str, tuple] = {}
        self._spec, self._spec_world, self._weights = spec, world, weights

    def get(self, world: World) -> Policy:
        with self._lock:
            if world.name not in self._policies:
                if world.name == self._spec_world:
                    policy = chosen_policy(world, self._spec, self._weights)
                else:
                    policy = base_policy(world)
                policy.fits(world)
                self._policies[world.name] = policy
            return self._policies[world.name]

    def known(self, world: World) -> tuple:
        """The base policy's training demonstrations (variant sources, replayed), where the
        world has a training distribution."""
        with self._lock:
            if world.name not in self._known:
                self._known[world.name] = tuple(training_demos(world)) if world.benchmark else ()
            return self._known[world.name]
