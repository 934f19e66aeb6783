"""The policy a command runs on a world by name, loaded once per process and checked to fit."""

from __future__ import annotations

import functools


@functools.lru_cache(maxsize=2)
def checked_policy(world: str, spec: str | None):
    """The policy of `spec` (a policy.outside spec; None: the world's base policy) on the world
    named `world`, checked to fit it (a bad spec or a misfit: one UserError, before any work).
    The last two asked for are kept, so a worker process loads each once."""
    from policy import base_policy
    from policy.outside import load
    from sim import get_world

    w = get_world(world)
    policy = load(spec, w) if spec is not None else base_policy(w)
    policy.fits(w)
    return policy
