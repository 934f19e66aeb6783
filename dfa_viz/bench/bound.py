"""The forward-pass bound of a search: the policy's forward passes over the very batches the
search ran, timed alone.

A lockstep search runs one batched forward pass per step over the candidates still live (the
whole wave at step 0, fewer as candidates are dropped). No search of this policy that
compares its actions step by step can take less time than those passes; a search's ratio to
the bound is what rendering, stepping and bookkeeping add.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dfa_viz.bench.timing import best_of
from policy import Policy
from search import Candidate

MIN_S = 0.2  # a search and its bound are each timed over at least this long (best run)


def step_batches(passes: Sequence[Sequence[Candidate]]) -> list[int]:
    """The batch size of every forward pass of a search: per lockstep pass (the candidates
    rolled out together), per step, how many candidates were still live."""
    sizes = []
    for cands in passes:
        live = np.isfinite(np.stack([c.distances for c in cands])).sum(axis=0)  # (T,)
        sizes += [int(n) for n in live if n > 0]
    return sizes


def waves(tried: Sequence[Candidate], wave: int) -> list[list[Candidate]]:
    """The lockstep passes of a size-by-size search (search.counterfactual_search): each
    size's candidates in their order, `wave` at a time."""
    out: list[list[Candidate]] = []
    by_size: dict[int, list[Candidate]] = {}
    for c in tried:
        by_size.setdefault(c.edit.size, []).append(c)
    for cands in by_size.values():
        out += [cands[i : i + wave] for i in range(0, len(cands), wave)]
    return out


def forward_bound_s(
    policy: Policy, frames: np.ndarray, batches: Sequence[int], repeats: int
) -> float:
    """Seconds the policy's forward passes over `batches` take (best of `repeats`), each pass
    on the first frames uint8 (N, H, W, 3) (N >= the largest batch), split into the policy's
    chunks as the search's are; runs repeated for at least MIN_S in all."""
    assert len(frames) >= max(batches), (len(frames), max(batches))

    def run() -> None:
        for b in batches:
            policy.outputs(frames[:b])

    return best_of(run, repeats, min_s=MIN_S)[0]
