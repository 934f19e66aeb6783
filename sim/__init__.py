"""Worlds for the DFA debugger, found by name in one registry (sim.registry). Light to import:
no torch, no MuJoCo, no minigrid until a world is built.

    register_world(name, factory)   add a world (factory: a callable, or "module:attribute");
                                    a name another factory holds is an error, never replaced
    register_spec(spec)             add the world "module:Class" names, under its own name
    world_names()                   every registered name, the built-in worlds first
    check_world_name(name)          the registered name `name` stands for, or a UserError
    get_world(name)                 the world of that name, built once per process

Names come from the built-in worlds below; installed packages that declare an entry point in
the group "dfa.worlds" (name = factory); the environment variable DFA_WORLDS
("mod:Class,mod2:Class2"); a --world given as "module:Class"; and name prefixes that make a
world from what follows them: "minigrid:<EnvId>[:tile=N][:view=partial]" turns any registered
MiniGrid environment into a world, "fetch:<EnvId>" any of gymnasium-robotics' Fetch tasks, and
"robosuite:<Env>[:robot=<Robot>][:camera=<camera>]" robosuite's Lift and Stack (both the
`robotics` extra).
"""

from __future__ import annotations

import gymnasium

from sim.registry import (
    ENTRY_POINTS,
    ENV_LIST,
    Factory,
    check_world_name,
    get_world,
    register_spec,
    register_world,
    world_names,
)

__all__ = [
    "ENTRY_POINTS",
    "ENV_LIST",
    "PAPER_WORLDS",
    "Factory",
    "check_world_name",
    "get_world",
    "register_spec",
    "register_world",
    "world_names",
]

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
register_world("fetch", "sim.fetch.world:fetch_world", prefix=True)
register_world("robosuite", "sim.robosuite.world:robosuite_world", prefix=True)
for _env_id, _entry in (
    ("dfa/Nav2D-v0", "sim.nav2d.env:Nav2DEnv"),
    ("dfa/DoorKey-v0", "sim.doorkey.env:DoorKeyEnv"),
    ("dfa/Tabletop-v0", "sim.tabletop.env:TabletopEnv"),
):
    if _env_id not in gymnasium.registry:
        gymnasium.register(id=_env_id, entry_point=_entry)
