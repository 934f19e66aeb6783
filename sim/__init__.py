"""Worlds for the DFA debugger, found by name in one registry. Light to import: no torch, no
MuJoCo, no minigrid until a world is built.

    register_world(name, factory)   add a world (factory: a callable, or "module:attribute")
    world_names()                   every registered name, the built-in worlds first
    check_world_name(name)          a UserError for a name no registration makes
    get_world(name)                 the world of that name, built once per process

Names come from three places: the built-in worlds below; installed packages that declare an
entry point in the group "dfa.worlds" (name = factory), read on first use; and name prefixes
that make a world from what follows them: "minigrid:<EnvId>[:tile=N][:view=partial]" turns
any registered MiniGrid environment into a world.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import threading
from collections.abc import Callable

import gymnasium

from sim.core.errors import UserError

ENTRY_POINTS = "dfa.worlds"
Factory = Callable[[], object] | str

_factories: dict[str, Factory] = {}
_prefixes: dict[str, Factory] = {}  # prefix -> factory(rest of the name)
_built: dict[str, object] = {}
_lock = threading.RLock()
_entry_points_read = False


def register_world(name: str, factory: Factory, *, prefix: bool = False) -> None:
    """Register a world: `factory()` builds it (or "module:attribute" names the factory, so
    that nothing is imported until the world is asked for). With `prefix`, `name` is a prefix
    and `factory(rest)` builds the world of the name "<prefix>:<rest>"."""
    if not name or ":" in name:
        raise UserError(f"a world name is non-empty and has no ':', not {name!r}")
    with _lock:
        (_prefixes if prefix else _factories)[name] = factory


def _resolve(factory: Factory) -> Callable:
    if callable(factory):
        return factory
    module, attribute = factory.split(":")
    return getattr(importlib.import_module(module), attribute)


def _read_entry_points() -> None:
    global _entry_points_read
    with _lock:
        if _entry_points_read:
            return
        _entry_points_read = True
        for ep in importlib.metadata.entry_points(group=ENTRY_POINTS):
            _factories.setdefault(ep.name, ep.value)


def world_names() -> tuple[str, ...]:
    """Every registered world name (built-ins first), and the prefixes as "<prefix>:..."."""
    _read_entry_points()
    with _lock:
        return (*_factories, *(f"{p}:..." for p in _prefixes))


def check_world_name(name: str) -> str:
    """`name` if it names a registered world (or a prefix's), else a UserError; builds nothing."""
    _read_entry_points()
    head, _, rest = name.partition(":")
    with _lock:
        if name in _factories or (rest and head in _prefixes):
            return name
    raise UserError(f"unknown world {name!r}; accepted: {', '.join(world_names())}")


def get_world(name: str):
    """The World registered as `name` (built once per process)."""
    _read_entry_points()
    with _lock:
        if name in _built:
            return _built[name]
        head, _, rest = name.partition(":")
        if name in _factories:
            world = _resolve(_factories[name])()
        elif rest and head in _prefixes:
            world = _resolve(_prefixes[head])(rest)
        else:
            raise UserError(f"unknown world {name!r}; accepted: {', '.join(world_names())}")
        _built[name] = world
        return world


# the built-in worlds, and their gymnasium environments
# the paper's three worlds, in its order: the experiments, the explanation benchmark and the
# study run on these
PAPER_WORLDS = ("nav2d", "doorkey", "tabletop")
for _name, _factory in zip(
    PAPER_WORLDS,
    (
        "sim.nav2d.world:Nav2DWorld",
        "sim.doorkey.world:DoorKeyWorld",
        "sim.tabletop.world:TabletopWorld",
    ),
    strict=True,
):
    register_world(_name, _factory)
register_world("minigrid", "sim.minigrid.world:minigrid_world", prefix=True)
for _env_id, _entry in (
    ("dfa/Nav2D-v0", "sim.nav2d.env:Nav2DEnv"),
    ("dfa/DoorKey-v0", "sim.doorkey.env:DoorKeyEnv"),
    ("dfa/Tabletop-v0", "sim.tabletop.env:TabletopEnv"),
):
    if _env_id not in gymnasium.registry:
        gymnasium.register(id=_env_id, entry_point=_entry)
