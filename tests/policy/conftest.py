"""What the tests of a committed MuJoCo base policy share."""

from __future__ import annotations

import json

import pytest

import sim
from policy.base import record_folder
from policy.checkpoint import load_policy
from policy.train import base_arch, base_config


@pytest.fixture
def committed():
    """name -> (world, recipe, policy): the world's committed base policy, its recipe's
    settings and architecture checked against today's."""

    def load(name: str):
        world = sim.get_world(name)
        folder = record_folder(world)
        recipe = json.loads((folder / "config.json").read_text())["meta"]["recipe"]
        assert recipe["train"] == json.loads(json.dumps(base_config(world).to_dict()))
        assert recipe["policy"] == json.loads(json.dumps(base_arch(world).to_dict()))
        return world, recipe, load_policy(folder, world=world)

    return load
