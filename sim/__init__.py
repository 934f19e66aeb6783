"""Worlds for the DFA debugger. Light to import: no torch, no MuJoCo until a world is built."""

from __future__ import annotations

import importlib

import gymnasium

from sim.core.errors import UserError

# world name -> (module:class of its World, gymnasium id, module:class of its env)
WORLDS: dict[str, tuple[str, str, str]] = {
    "nav2d": ("sim.nav2d.world:Nav2DWorld", "dfa/Nav2D-v0", "sim.nav2d.env:Nav2DEnv"),
    "tabletop": (
        "sim.tabletop.world:TabletopWorld",
        "dfa/Tabletop-v0",
        "sim.tabletop.env:TabletopEnv",
    ),
    "doorkey": ("sim.doorkey.world:DoorKeyWorld", "dfa/DoorKey-v0", "sim.doorkey.env:DoorKeyEnv"),
}

for _world, _env_id, _entry in WORLDS.values():
    if _env_id not in gymnasium.registry:
        gymnasium.register(id=_env_id, entry_point=_entry)

_cache: dict[str, object] = {}


def get_world(name: str):
    """The World registered as `name` (built once per process; one per world at most)."""
    if name not in WORLDS:
        raise UserError(f"unknown world {name!r}; accepted: {', '.join(WORLDS)}")
    if name not in _cache:
        module, cls = WORLDS[name][0].split(":")
        _cache[name] = getattr(importlib.import_module(module), cls)()
    return _cache[name]
