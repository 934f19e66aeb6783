"""One contract for every world (sim.contract, the same checks `dfa check-world` runs): the
registered ones, MiniGrid environments, gymnasium-robotics' Fetch tasks and robosuite's Lift
and Stack made into worlds, and the example worlds of
docs/bring-your-own.md — corridor (a World written out) and gridreacher (a gymnasium
environment through sim.gymenv). A world is tested the day it exists."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import sim
from sim.contract import CONTRACTS, check_world, expect

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
MINIGRID = [
    "minigrid:MiniGrid-DoorKey-5x5-v0",
    "minigrid:MiniGrid-DoorKey-8x8-v0",
    "minigrid:MiniGrid-Unlock-v0",
    "minigrid:MiniGrid-LavaGapS5-v0",
    "minigrid:MiniGrid-Fetch-5x5-N2-v0",
    "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12",
]
FETCH = [
    "fetch:FetchPickAndPlace-v4",
    "fetch:FetchPush-v4",
    "fetch:FetchSlide-v4",
    "fetch:FetchReach-v4",
]
ROBOSUITE = ["robosuite:Lift", "robosuite:Stack"]


def _register_examples() -> None:
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    sim.register_world("corridor", "corridor:CorridorWorld")
    sim.register_spec("grid_reacher:reacher")


_register_examples()
WORLDS = [n for n in sim.world_names() if not n.endswith(":...")] + MINIGRID + FETCH + ROBOSUITE


@pytest.fixture(scope="module", params=WORLDS)
def world(request):
    return sim.get_world(request.param)


@pytest.mark.parametrize("check", [c for _, c in CONTRACTS], ids=[c.__name__ for _, c in CONTRACTS])
def test_contract(world, check):
    check(world)


def test_the_example_worlds_are_in_the_registry():
    assert {"corridor", "gridreacher"} <= set(WORLDS)


def test_a_broken_world_fails_the_contract_with_a_line_per_part():
    """The contract can fail: a world whose batch render differs from its single render, and
    whose step raises, fails those parts with their reasons and passes the rest."""
    import numpy as np
    from corridor import CorridorWorld

    class Broken(CorridorWorld):
        name = "broken-corridor"

        def render_batch(self, scenes):
            frames = super().render_batch(scenes)
            frames[1:] ^= 1  # every frame but the first of a batch off by one bit
            return frames

        def step_batch(self, scenes, actions):
            raise RuntimeError("the physics engine is not running")

    results = {r.name: r for r in check_world(Broken())}
    assert not results["rendering"].passed
    assert "differs from its batch frame" in results["rendering"].message
    assert not results["stepping"].passed
    assert results["stepping"].message == "RuntimeError: the physics engine is not running"
    assert results["capabilities"].passed and results["encode/decode and edit round trips"].passed
    assert all("\n" not in r.message for r in results.values())
    with pytest.raises(AssertionError, match="wrong"):
        expect(np.int64(0) > 1, "wrong")
