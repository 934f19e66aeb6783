"""The registry of worlds: every name a command's --world accepts, and how each world is built.

    register_world(name, factory)   add a world (factory: a callable, or "module:attribute");
                                    a name taken by another factory is a UserError
    register_spec(spec)             add the world "module:attribute" names, under its own name
    world_names()                   every registered name, the built-in worlds first
    check_world_name(name)          the registered name `name` stands for, or a UserError
    get_world(name)                 the world of that name, built once per process

A world comes from one of five places: the built-in worlds (sim/__init__.py); installed
packages that declare an entry point in the group "dfa.worlds" (name = "module:attribute"),
read on first use; the environment variable DFA_WORLDS, a comma-separated list of
"module:attribute" specs, read on first use (and again when it changes); a name given as
"module:attribute" itself (`--world my_worlds:Reacher`), imported when asked for; and name
prefixes that make a world from what follows them ("minigrid:<EnvId>[:tile=N]").

A "module:attribute" spec names a World subclass or a function that returns a World; the world
is registered under its own `name`. A module that is not importable from sys.path is looked for
in the current folder too (as `python -m` would find it).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import re
import sys
import threading
from collections.abc import Callable

from sim.core.errors import UserError

ENTRY_POINTS = "dfa.worlds"
ENV_LIST = "DFA_WORLDS"
Factory = Callable[[], object] | str
SPEC = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")  # "package.module:Attribute"

_factories: dict[str, Factory] = {}
_prefixes: dict[str, Factory] = {}  # prefix -> factory(rest of the name)
_specs: dict[str, str] = {}  # "module:attribute" -> the name its world was registered under
_built: dict[str, object] = {}
_outside: set[str] = set()  # names whose code came from outside: its failures are one line
_lock = threading.RLock()
_entry_points_read = False
_env_read = ""  # the value of DFA_WORLDS last read


def callable_name(factory: Callable | str) -> str:
    """ "module:qualname" of a callable, or the "module:attribute" string that names one."""
    if isinstance(factory, str):
        return factory
    return f"{getattr(factory, '__module__', '?')}:{getattr(factory, '__qualname__', factory)}"


def register_world(name: str, factory: Factory, *, prefix: bool = False) -> None:
    """Register a world: `factory()` builds it (or "module:attribute" names the factory, so
    that nothing is imported until the world is asked for). With `prefix`, `name` is a prefix
    and `factory(rest)` builds the world of the name "<prefix>:<rest>". Registering the same
    factory again changes nothing; a name another factory holds is a UserError (nothing is
    replaced)."""
    if not isinstance(name, str) or not name or ":" in name or name != name.strip():
        raise UserError(f"a world name is non-empty and has no ':' or outer spaces, not {name!r}")
    with _lock:
        table, other = (_prefixes, _factories) if prefix else (_factories, _prefixes)
        old = table.get(name, other.get(name))
        if old is not None and (name in other or old != factory):
            raise UserError(
                f"a world named {name!r} is already registered ({callable_name(old)}); "
                f"register {callable_name(factory)} under another name"
            )
        table[name] = factory


def _import(module: str):
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name is None or module.split(".")[0] != e.name.split(".")[0]:
            raise
        if os.getcwd() in sys.path or "" in sys.path:
            raise
        sys.path.append(os.getcwd())  # a module in the folder the command runs in
        return importlib.import_module(module)


def _resolve(factory: Factory) -> Callable:
    if callable(factory):
        return factory
    module, attribute = factory.split(":")
    target = _import(module)
    for part in attribute.split("."):
        target = getattr(target, part)
    return target


def register_spec(spec: str, *, where: str = "") -> str:
    """Import the World subclass (or function returning a World) that "module:attribute"
    names and register it under its world's `name`; returns that name. `where` says where the
    spec came from, for the error line."""
    with _lock:
        if spec in _specs:
            return _specs[spec]
    said = f"{where}: " if where else ""
    if not SPEC.match(spec):
        raise UserError(f"{said}{spec!r} is not module:Class (a World subclass to import)")
    try:
        target = _resolve(spec)
    except ModuleNotFoundError as e:
        raise UserError(
            f"{said}{spec}: no module {e.name!r} on the Python path or in the current folder "
            "(add its folder to PYTHONPATH)"
        ) from None
    except AttributeError:
        module, attribute = spec.split(":")
        raise UserError(f"{said}{spec}: module {module} has no {attribute}") from None
    except (Exception, SystemExit) as e:  # the module's own code failed as it was imported
        raise UserError(f"{said}{spec}: importing it raised {type(e).__name__}: {e}") from None
    if not callable(target):
        raise UserError(
            f"{said}{spec}: names a {type(target).__name__}, not a World subclass or a function "
            "returning a World"
        )
    name = target.__dict__.get("name") if isinstance(target, type) else None
    world = None
    if not isinstance(name, str):  # a function, or a class that names itself when built
        world = _build(spec, target, said)
        name = world.name
    register_world(name, spec)
    with _lock:
        _specs[spec] = name
        _outside.add(name)
        if world is not None:
            _built.setdefault(name, world)
    return name


def _build(name: str, factory: Callable, said: str = "", *, outside: bool = True):
    """factory(), checked to be a World; an outside world's failure is one UserError line."""
    from sim.core.world import World

    try:
        world = factory()
    except UserError:
        raise
    except (Exception, SystemExit) as e:
        if not outside:
            raise
        raise UserError(
            f"{said}{name}: building the world raised {type(e).__name__}: {e}"
        ) from None
    if not isinstance(world, World):
        raise UserError(
            f"{said}{name}: gave a {type(world).__name__}, not a sim.core.World (subclass it)"
        )
    return world


def _read_outside() -> None:
    """Entry points (once) and DFA_WORLDS (whenever it changes) into the registry."""
    global _entry_points_read, _env_read
    with _lock:
        if not _entry_points_read:
            _entry_points_read = True
            for ep in importlib.metadata.entry_points(group=ENTRY_POINTS):
                dist = getattr(ep.dist, "name", "a package")
                if ep.name in _factories and _factories[ep.name] != ep.value:
                    raise UserError(
                        f"the {ENTRY_POINTS} entry point {ep.name} = {ep.value} of {dist} names "
                        "a world already registered "
                        f"({callable_name(_factories[ep.name])}); rename it"
                    )
                register_world(ep.name, ep.value)
                _outside.add(ep.name)
        listed = os.environ.get(ENV_LIST, "")
        if listed != _env_read:
            _env_read = listed
            for spec in filter(None, (s.strip() for s in listed.split(","))):
                register_spec(spec, where=ENV_LIST)


def world_names() -> tuple[str, ...]:
    """Every registered world name (built-ins first), and the prefixes as "<prefix>:..."."""
    _read_outside()
    with _lock:
        return (*_factories, *(f"{p}:..." for p in _prefixes))


def _registered(name: str) -> str | None:
    """The registered name `name` stands for (itself, or a spec's world), or None."""
    head, _, rest = name.partition(":")
    with _lock:
        if name in _factories or (rest and head in _prefixes):
            return name
        return _specs.get(name)


def _unknown(name: str) -> UserError:
    return UserError(f"unknown world {name!r}; accepted: {', '.join(world_names())}, module:Class")


def check_world_name(name: str) -> str:
    """The registered name `name` stands for (itself, or the name of the world a
    "module:Class" names), else a UserError. Builds nothing, but a "module:Class" name is
    imported (and registered) to learn what world it names."""
    _read_outside()
    registered = _registered(name)
    if registered is not None:
        return registered
    if not SPEC.match(name):
        raise _unknown(name)
    return register_spec(name)


def get_world(name: str):
    """The World registered as `name` (built once per process); a "module:Class" name is
    imported and registered first."""
    _read_outside()
    registered = _registered(name)
    if registered is None:
        if not SPEC.match(name):
            raise _unknown(name)
        registered = register_spec(name)
    with _lock:
        if registered in _built:
            return _built[registered]
        head, _, rest = registered.partition(":")
        if registered in _factories:
            outside = registered in _outside
            try:
                factory = _resolve(_factories[registered])
            except (Exception, SystemExit) as e:
                if not outside:
                    raise
                raise UserError(
                    f"{registered}: importing it raised {type(e).__name__}: {e}"
                ) from None
            world = _build(registered, factory, outside=outside)
        else:
            world = _resolve(_prefixes[head])(rest)
        _built[registered] = world
        return world
