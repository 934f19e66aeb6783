"""Edit enumeration: counts without listing, and size-3 edits generated lazily in cost order."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from search import combinations, count
from sim import get_world
from sim.core import Edit, effective, single_changes


def _brute(space, scene, size: int) -> set[Edit]:
    presence, values = single_changes(space, scene)
    out = set()
    for combo in itertools.combinations(presence + values, size):
        if len({(c.slot, c.concept) for c in combo}) == size:
            edit = Edit(frozenset(combo))
            if effective(scene, edit):
                out.add(edit)
    return out


def _scenes(world):
    tasks = [world.train_task(0)] + [world.test_task(s, 1) for s in world.shifts]
    return [t.scene for t in tasks]


@pytest.mark.parametrize(
    "name,sizes", [("nav2d", (1, 2, 3)), ("doorkey", (1, 2, 3)), ("tabletop", (1, 2))]
)
def test_count_is_the_number_of_edits_listed(name, sizes):
    world = get_world(name)
    for scene in _scenes(world):
        for k in sizes:
            assert count(world.space, scene, k) == len(_brute(world.space, scene, k)), (scene, k)


@pytest.mark.parametrize("name", ["nav2d", "doorkey"])
def test_size_three_comes_cheapest_first_and_complete(name):
    world = get_world(name)
    rng = np.random.default_rng(0)
    for scene in _scenes(world):
        presence, values = single_changes(world.space, scene)
        # a prior with ties and with changes left out (cost +inf), as the search's has
        prior = {c: float(rng.integers(0, 5)) for c in presence + values if rng.random() < 0.8}
        got = list(combinations(world.space, scene, 3, prior=prior))
        assert len(got) == len(set(got)) and set(got) == _brute(world.space, scene, 3)
        costs = [sum(prior.get(c, np.inf) for c in e.changes) for e in got]
        assert costs == sorted(costs)
        plain = list(combinations(world.space, scene, 3))  # no prior: presence first, lazily
        assert set(plain) == set(got)
        first_plain = next((i for i, e in enumerate(plain) if not e.is_presence), len(plain))
        assert all(e.is_presence for e in plain[:first_plain])
        assert not any(e.is_presence for e in plain[first_plain:])


def test_size_three_on_the_tabletop_starts_without_listing_every_edit():
    world = get_world("tabletop")
    scene = world.train_task(0).scene
    presence, values = single_changes(world.space, scene)
    prior = {c: float(i % 97) for i, c in enumerate(presence + values)}
    first = list(itertools.islice(combinations(world.space, scene, 3, prior=prior), 2000))
    assert count(world.space, scene, 3) > 500_000 and len(first) == 2000
    costs = [sum(prior[c] for c in e.changes) for e in first]
    assert costs == sorted(costs) and costs[0] == min(costs)
