"""Edit enumeration: by size, presence first, ordered by a cheap prior inside each group."""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Mapping

from sim.core import PRESENCE, Change, ConceptSpace, Edit, Scene, effective, single_changes


def singles(space: ConceptSpace, scene: Scene) -> list[Edit]:
    """All effective size-1 edits of `scene`, presence changes first."""
    presence, values = single_changes(space, scene)
    return [e for e in (Edit.of(c) for c in presence + values) if effective(scene, e)]


def combinations(
    space: ConceptSpace,
    scene: Scene,
    size: int,
    *,
    prior: Mapping[Change, float] | None = None,
) -> Iterator[Edit]:
    """Effective edits of exactly `size` changes: those with a presence change first.

    Inside each group, edits come in ascending order of the summed prior of their changes
    (e.g. each single change's first-step action distance: the smaller, the more promising).
    Changes missing from `prior` count as +inf. Without a prior, the order is enumeration order.
    """
    presence, values = single_changes(space, scene)
    changes = presence + values

    def cost(edit: Edit) -> float:
        if prior is None:
            return 0.0
        return sum(prior.get(c, float("inf")) for c in edit.changes)

    groups: tuple[list[Edit], list[Edit]] = ([], [])
    for combo in itertools.combinations(changes, size):
        if len({(c.slot, c.concept) for c in combo}) < size:
            continue
        edit = Edit(frozenset(combo))
        if effective(scene, edit):
            groups[0 if edit.is_presence else 1].append(edit)
    for group in groups:
        group.sort(key=cost)  # stable: ties keep enumeration order
        yield from group


def count(space: ConceptSpace, scene: Scene, size: int) -> int:
    """How many effective edits of `size` changes there are."""
    return sum(1 for _ in combinations(space, scene, size))


__all__ = ["PRESENCE", "combinations", "count", "singles"]
