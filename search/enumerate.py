"""Edit enumeration: by size, presence first, ordered by a cheap prior inside each group."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator, Mapping

from sim.core import PRESENCE, PRESENT, Change, ConceptSpace, Edit, Scene, effective, single_changes


def singles(space: ConceptSpace, scene: Scene) -> list[Edit]:
    """All effective size-1 edits of `scene`, presence changes first."""
    presence, values = single_changes(space, scene)
    return [e for e in (Edit.of(c) for c in presence + values) if effective(scene, e)]


LAZY_FROM = 3
"""Edits of this size or more are generated as they are tried, never all listed first (the
tabletop has over half a million edits of size 3)."""


def combinations(
    space: ConceptSpace,
    scene: Scene,
    size: int,
    *,
    prior: Mapping[Change, float] | None = None,
    grouped: bool = True,
) -> Iterator[Edit]:
    """Effective edits of exactly `size` changes: those with a presence change first.

    Inside each group, edits come in ascending order of the summed prior of their changes
    (e.g. each single change's first-step action distance: the smaller, the more promising),
    ties in enumeration order. Changes missing from `prior` count as +inf. Without a prior, the
    order is enumeration order. From size LAZY_FROM on, edits are generated lazily, and with a
    prior in ascending cost alone, presence or not (the tabletop has 83,856 size-3 edits with
    a presence change: trying them all first took 45-60 s before a size-3 cause of looks).
    grouped=False drops the presence-first group below LAZY_FROM too: one order by cost alone
    (a learned prior that prices presence changes itself, search.prior).
    """
    presence, values = single_changes(space, scene)
    changes = presence + values
    if size >= LAZY_FROM:
        if prior is not None:  # by cost alone: there are too many presence edits to go first
            yield from _cheapest_first(changes, size, prior, lambda e: effective(scene, e))
            return
        for wanted in (True, False):
            yield from (
                e
                for e in map(_edit, _distinct(changes, size))
                if e.is_presence == wanted and effective(scene, e)
            )
        return

    # each change's prior once, by its place in `changes` (a sum of two costs is the same
    # number in either order: the order is that of the summed prior)
    costs = [0.0] * len(changes) if prior is None else [prior.get(c, math.inf) for c in changes]
    groups: tuple[list[tuple[float, Edit]], list[tuple[float, Edit]]] = ([], [])
    there = {o.slot: o.present for o in scene.objects}
    for idx in _distinct_at(changes, size):
        combo = tuple(changes[i] for i in idx)
        if _shows(combo, there):  # what `effective` says, before an Edit is built
            edit = Edit(frozenset(combo))
            cost = costs[idx[0]] if size == 1 else sum(costs[i] for i in idx)
            groups[0 if edit.is_presence and grouped else 1].append((cost, edit))
    for group in groups:
        group.sort(key=lambda ce: ce[0])  # stable: ties keep enumeration order
        yield from (e for _, e in group)


def _edit(combo: tuple[Change, ...]) -> Edit:
    return Edit(frozenset(combo))


def _distinct(changes: list[Change], size: int) -> Iterator[tuple[Change, ...]]:
    """itertools.combinations(changes, size), in its order, less those that change one
    (slot, concept) twice."""
    for idx in _distinct_at(changes, size):
        yield tuple(changes[i] for i in idx)


def _distinct_at(changes: list[Change], size: int) -> Iterator[tuple[int, ...]]:
    """_distinct's combinations as the places of their changes in `changes`."""
    keys = [(c.slot, c.concept) for c in changes]
    if size == 2:  # the common size, without a set per pair: a concept's changes come together
        end = list(range(1, len(keys) + 1))  # end of each change's run of its (slot, concept)
        for i in range(len(keys) - 2, -1, -1):
            if keys[i] == keys[i + 1]:
                end[i] = end[i + 1]
        if len(set(keys)) == sum(1 for i, e in enumerate(end) if i == 0 or end[i - 1] != e):
            for i in range(len(changes)):
                for j in range(end[i], len(changes)):
                    yield i, j
            return
    for idx in itertools.combinations(range(len(changes)), size):
        if len({keys[i] for i in idx}) == size:
            yield idx


def _shows(combo: tuple[Change, ...], there: Mapping[str, bool]) -> bool:
    """sim.core.effective on a combination of changes: no change of looks to an object that is
    absent after it."""
    for c in combo:
        if c.concept == PRESENCE:
            continue
        present = there[c.slot]
        for d in combo:
            if d.slot == c.slot and d.concept == PRESENCE:
                present = d.new == PRESENT
        if not present:
            return False
    return True


def _cheapest_first(
    changes: list[Change],
    size: int,
    prior: Mapping[Change, float],
    pick: Callable[[Edit], bool],
    band: int = 4096,
) -> Iterator[Edit]:
    """The edits of `size` changes that `pick` keeps, in ascending summed cost (ties in
    enumeration order), generated band by band: a band holds the combinations whose cost lies
    in (lo, hi]; its width doubles while bands hold fewer than `band` combinations, and the
    last band takes every cost left (+inf included)."""
    costs = [prior.get(c, math.inf) for c in changes]
    order = sorted(range(len(changes)), key=lambda i: (costs[i], i))
    ranked = [costs[i] for i in order]  # ascending
    finite = [c for c in ranked if math.isfinite(c)]
    if len(ranked) < size:
        return
    top = sum(finite[-size:]) if len(finite) >= size else -math.inf  # dearest finite cost
    lo, hi = -math.inf, sum(ranked[:size])
    width = max((top - hi) / 64, 1e-6) if math.isfinite(hi) else math.inf
    while True:
        if hi >= top:
            hi = math.inf
        found = _band(changes, size, order, ranked, lo, hi)
        for _, idx in found:
            edit = Edit(frozenset(changes[i] for i in idx))
            if pick(edit):
                yield edit
        if hi == math.inf:
            return
        if len(found) < band:
            width *= 2
        lo, hi = hi, hi + width


def _band(
    changes: list[Change],
    size: int,
    order: list[int],
    ranked: list[float],
    lo: float,
    hi: float,
) -> list[tuple[float, tuple[int, ...]]]:
    """(cost, change indices in enumeration order) of every combination of `size` changes of
    distinct (slot, concept) with lo < cost <= hi, sorted: a depth-first walk over the changes
    by ascending cost that turns back wherever the cheapest completion costs more than hi."""
    keys = [(changes[i].slot, changes[i].concept) for i in order]
    slack = hi + abs(hi) * 1e-9 + 1e-12 if math.isfinite(hi) else hi  # sums round differently
    found: list[tuple[float, tuple[int, ...]]] = []
    stack: list[tuple[int, tuple[int, ...], float]] = [(0, (), 0.0)]
    while stack:
        start, picked, total = stack.pop()
        left = size - len(picked)
        if left == 0:
            if lo < total <= hi:
                found.append((total, tuple(sorted(order[i] for i in picked))))
            continue
        used = {keys[i] for i in picked}
        for j in range(start, len(ranked) - left + 1):
            if total + sum(ranked[j : j + left]) > slack:
                break  # every later j costs at least as much
            if keys[j] not in used:
                stack.append((j + 1, (*picked, j), total + ranked[j]))
    found.sort()
    return found


def count(space: ConceptSpace, scene: Scene, size: int) -> int:
    """How many effective edits of `size` changes there are (what `combinations` yields),
    counted without listing them: per slot, a polynomial in x whose k-th coefficient counts
    that slot's ways to take k changes (at most one value per concept; appearance changes only
    of an object there after the edit), multiplied over the slots."""
    total = [1]  # coefficients, x^0 first
    for s in space.slots:
        obj = scene.obj(s.name)
        looks = [1]
        for c in s.concepts:
            others = sum(1 for v in c.values if v != obj.value(c.name))
            looks = _times(looks, [1, others])
        if not s.optional:
            slot = looks
        elif obj.present:  # keep it (any looks), or remove it (no looks)
            slot = _plus(looks, [0, 1])
        else:  # leave it out (no looks), or add it (any looks)
            slot = _plus([1], _times([0, 1], looks))
        total = _times(total, slot)
    return total[size] if size < len(total) else 0


def _times(a: list[int], b: list[int]) -> list[int]:
    out = [0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return out


def _plus(a: list[int], b: list[int]) -> list[int]:
    return [
        (a[i] if i < len(a) else 0) + (b[i] if i < len(b) else 0)
        for i in range(max(len(a), len(b)))
    ]


__all__ = ["PRESENCE", "combinations", "count", "singles"]
