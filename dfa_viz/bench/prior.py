"""The learned search prior against enumeration and the first-step prior, on planted tasks.

Per world: a LearnedPrior (search.prior) fitted on planted size-2 tasks from seeds 0 on, then
evaluated on planted size-2 tasks from EVAL_FROM on (a disjoint range). Each evaluation task's
every edit up to size 2 is rolled out once (the complete search that accepts it); each order's
rank of the first valid size-2 edit is read from that one pass: enumeration (no prior), the
first-step prior (SearchConfig's default) and the learned prior.

Target on the tabletop: the learned prior's first valid edit within the first 1% of the
size-2 candidates on 90% of the tasks.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from policy import base_policy
from search import combinations
from search.planted import Planted, fit_on_planted, planted_tasks
from search.prior import LearnedPrior, unedited_candidate
from sim import get_world
from sim.core import Change, Edit, UserError

EVAL_FROM = 1_000_000  # first evaluation seed; fitting takes seeds from 0 up
ORDERS = ("enumeration", "first-step prior", "learned prior")
TARGETS = {"tabletop": 0.01}  # world -> share of size-2 candidates the p90 rank must stay within


@dataclass(frozen=True)
class Ranked:
    """One evaluation task: its size-2 candidates and each order's first valid one.

    ranks: per order (ORDERS), the 1-based rank of the first valid edit among the size-2
        candidates in that order.
    """

    seed: int
    singles: int
    pairs: int
    ranks: tuple[int, ...]


def rank_orders(world, policy, planted: Planted, learned: LearnedPrior) -> Ranked:
    """Each order's rank of the first valid size-2 edit, from the complete search's pass."""
    valid: dict[Edit, bool] = {c.edit: c.valid for c in planted.result.tried if c.edit.size == 2}
    singles = [c for c in planted.result.tried if c.edit.size == 1]
    scene = planted.task.scene
    first_step: dict[Change, float] = {
        next(iter(c.edit.changes)): float(c.distances[0]) for c in singles
    }
    unedited = unedited_candidate(world, policy, scene, planted.demo)
    orders = (
        combinations(world.space, scene, 2),
        combinations(world.space, scene, 2, prior=first_step),
        combinations(
            world.space,
            scene,
            2,
            prior=learned.costs(world.space, singles, unedited),
            grouped=False,
        ),
    )
    ranks = tuple(next(i + 1 for i, e in enumerate(order) if valid[e]) for order in orders)
    return Ranked(planted.task.seed, len(singles), len(valid), ranks)


def bench_prior(name: str, *, n_fit: int = 50, n_eval: int = 100, progress: bool = True) -> dict:
    """Fit on n_fit planted size-2 tasks, evaluate on n_eval; the figures and their timings.

    Returns: per order (ORDERS) the median and 90th percentile of the rank of the first valid
    size-2 edit and of the candidates tried before it (singles included); the tasks counted,
    the seeds tried, the distinct scenes, and the seconds spent fitting (planted tasks and
    their searches included), evaluating (the same) and ranking.
    """
    if n_fit < 1 or n_eval < 1:
        raise UserError(f"the prior needs tasks to fit and evaluate on, not {n_fit} and {n_eval}")
    world = get_world(name)
    policy = base_policy(world)
    bar = tqdm(total=n_fit, desc=f"{name}: planted tasks to fit on", disable=not progress)
    t0 = time.perf_counter()
    learned, fitted = fit_on_planted(
        world, policy, n=n_fit, on_seed=lambda _s, ok: bar.update(int(ok))
    )
    fit_s = time.perf_counter() - t0
    bar.close()
    bar = tqdm(total=n_eval, desc=f"{name}: planted tasks to evaluate", disable=not progress)
    tried: list[int] = []

    def seen(seed: int, ok: bool) -> None:
        tried.append(seed)
        bar.update(int(ok))

    t0 = time.perf_counter()
    evals = list(planted_tasks(world, policy, itertools.count(EVAL_FROM), 2, n_eval, on_seed=seen))
    eval_s = time.perf_counter() - t0
    bar.close()
    t0 = time.perf_counter()
    ranked = [rank_orders(world, policy, p, learned) for p in evals]
    rank_s = time.perf_counter() - t0
    ranks = np.array([r.ranks for r in ranked], np.float64)  # (N, 3)
    pairs = np.array([r.pairs for r in ranked], np.float64)  # (N,)
    before = ranks - 1 + np.array([r.singles for r in ranked])[:, None]  # (N, 3)
    share = ranks / pairs[:, None]  # (N, 3)
    fit_scenes = {p.task.scene for p in fitted}
    return {
        "world": name,
        "tasks": len(ranked),
        "fit_tasks": len(fitted),
        "seeds_tried": len(tried),
        "distinct_scenes": len({p.task.scene for p in evals}),
        "seen_when_fitting": sum(p.task.scene in fit_scenes for p in evals),
        "pairs_median": float(np.median(pairs)),
        "orders": {
            order: {
                "rank_median": float(np.median(ranks[:, i])),
                "rank_p90": float(np.percentile(ranks[:, i], 90)),
                "before_median": float(np.median(before[:, i])),
                "before_p90": float(np.percentile(before[:, i], 90)),
                "share_p90": float(np.percentile(share[:, i], 90)),
                "within_1pct": float(np.mean(share[:, i] <= 0.01)),
            }
            for i, order in enumerate(ORDERS)
        },
        "fit_s": fit_s,
        "eval_s": eval_s,
        "rank_s": rank_s,
    }


def prior_rows(r: dict) -> list[tuple[str, str, str, bool | None]]:
    """The figures of bench_prior() as (what, value, target, met) rows for `dfa bench`."""
    name, rows = r["world"], []
    target = TARGETS.get(name)
    for order in ORDERS:
        o = r["orders"][order]
        met = None
        goal = ""
        if target is not None and order == "learned prior":
            goal = f"p90 <= {target:.0%} of size-2 candidates"
            met = o["share_p90"] <= target
        rows.append(
            (
                f"{name}: first valid size-2 edit on {r['tasks']} planted tasks, {order} "
                f"(rank among ~{r['pairs_median']:.0f} size-2 candidates, median / p90; "
                f"candidates tried before it incl. singles; tasks within the first 1%)",
                f"rank {o['rank_median']:.0f} / {o['rank_p90']:.0f}; before "
                f"{o['before_median']:.0f} / {o['before_p90']:.0f}; {o['within_1pct']:.0%}",
                goal,
                met,
            )
        )
    rows.append(
        (
            f"{name}: learned prior fitted on {r['fit_tasks']} planted tasks, evaluated on "
            f"{r['tasks']} ({r['seeds_tried']} seeds tried, {r['distinct_scenes']} distinct "
            f"scenes, {r['seen_when_fitting']} also among the fitted); fit / evaluation / ranks",
            f"{r['fit_s']:.1f} / {r['eval_s']:.1f} / {r['rank_s']:.1f} s",
            "",
            None,
        )
    )
    return rows


if __name__ == "__main__":
    import sys

    from sim import PAPER_WORLDS

    for world_name in sys.argv[1:] or PAPER_WORLDS:
        for what, value, goal, ok in prior_rows(bench_prior(world_name)):
            print(f"{what}: {value} {goal} {'' if ok is None else ('met' if ok else 'NOT met')}")
