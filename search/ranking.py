"""The concepts of a scene ranked by a counterfactual search: what its answer blames, in order.

The search's own order, read as a ranking of the concepts a person can point at
(sim.core.visible.visible_concepts): first the concepts its best edit changes, then those of
the other counterfactuals in their order, then every other concept by the closest candidate
that changed it (a candidate that followed the demonstration for more steps is closer; among
equals, the smaller summed action distance). Inside an edit of several changes, a change comes
before another when its single edit was closer. Concepts no candidate changed come last, in
the space's order.
"""

from __future__ import annotations

from search.counterfactual import SearchResult
from search.lockstep import Candidate
from sim.core import Change, ConceptSpace, Scene
from sim.core.visible import visible_concepts


def _closeness(c: Candidate) -> tuple[int, float]:
    """Sort key of a candidate that is not a counterfactual: later drops first, then distance."""
    followed = len(c.distances) if c.dropped_at is None else c.dropped_at
    return (-followed, c.total)


def concept_ranking(space: ConceptSpace, scene: Scene, result: SearchResult) -> tuple[str, ...]:
    """Every user concept visible in `scene` (its name, "goal.colour"), most blamed first."""
    visible = [uc.name for uc in visible_concepts(space, scene)]
    shown = set(visible)
    valid = set(map(id, result.counterfactuals))
    rest = sorted((c for c in result.tried if id(c) not in valid), key=_closeness)
    order = [*result.counterfactuals, *rest]
    single: dict[Change, int] = {}
    for i, cand in enumerate(order):
        if cand.edit.size == 1:
            single.setdefault(next(iter(cand.edit.changes)), i)
    ranking: list[str] = []
    for cand in order:
        for change in sorted(cand.edit.changes, key=lambda ch: (single.get(ch, len(order)), ch)):
            name = space.user_concept(change.slot, change.concept).name
            if name in shown and name not in ranking:
                ranking.append(name)
    return (*ranking, *(n for n in visible if n not in ranking))
