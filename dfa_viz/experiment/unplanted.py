"""`dfa experiment unplanted`: the search, the saliency methods and the learned prior on
failures the benchmark's generator did not plant (search.unplanted), against ground truth from
exhaustive interventions.

Per failing task (all distinct), one row of tasks.csv:
- the ground truth: every edit of size 1 and 2 rolled out under R' (search.unplanted.
  ground_truth); its minimal size (or none within 2), how many minimal edits restore success,
  and, for generated tasks, whether undoing the generator's changes is one of them;
- the counterfactual search (search.counterfactual_search, the world's defaults, up to size 2):
  whether its best edit is a minimal ground-truth edit, whether it restores success at all,
  its size against the minimal size, its rollouts;
- the learned prior (search.prior, fitted on planted size-2 tasks of seeds disjoint from these,
  or, with prior=OTHERS, cross-fitted: each task's prior on the run's other tasks, their size-1
  passes labelled by their exhaustive ground truth, never on the task itself; none: not
  measured): the rank of the first ground-truth edit among the edits of the minimal size in the
  prior's order, beside plain enumeration's.
Per task, saliency method and readout, one row of saliency.csv: whether the first concept of
the readout's ranking (policy.concept_saliency, the explainer benchmark's readouts) belongs to
an object a minimal ground-truth edit changes (object top-1); a seeded random order is the floor.
A policy the saliency methods cannot take apart (policy.saliency.check_explainable: a network
that does not declare policy.model.Explainable) has no saliency rows, the random floor's
included; the project's image policies and outside stable-baselines3 CNN policies have them.
The table is unplanted_table.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from dfa_viz.experiment.explain import task_id
from policy.methods import METHODS
from search.unplanted import GroundTruth, Unplanted, ground_truth, rank_in

TASK_COLUMNS = (
    "world",
    "policy",
    "kind",
    "run_seed",
    "task_seed",
    "task_id",
    "changes",
    "edits_1",
    "edits_2",
    "gt_size",
    "gt_count",
    "gt_edits",
    "gt_objects",
    "undo_minimal",
    "undo_restores",
    "cf_size",
    "cf_edit",
    "cf_in_gt",
    "cf_restores",
    "cf_rollouts",
    "gt_rollouts",
    "prior_rank",
    "enum_rank",
    "n_at_size",
    "seconds",
)
SALIENCY_COLUMNS = ("world", "policy", "kind", "task_id", "method", "reading", "span", "top", "hit")
NONE = "-"
OTHERS = "others"
"""prior=OTHERS: each task's prior cross-fitted on the run's other tasks (leave one out)."""
PRIOR_SCENES = 100
"""Cross-fitting: the value frequencies come from training seeds 0 .. PRIOR_SCENES-1."""


def _yes(x: bool | None) -> str:
    return NONE if x is None else str(int(bool(x)))


def measure(
    world,
    policy,
    u: Unplanted,
    *,
    prior,
    policy_name: str,
    run_seed: int,
    methods: Sequence[str] = METHODS,
    logs: list | None = None,
) -> tuple[dict, list[dict]]:
    """One task: its tasks.csv row and its saliency.csv rows (strings). `logs`: a list the
    task's SearchLog (its size-1 pass, labelled by the ground truth) is appended to, for
    cross-fitting (`cross_fitted`); prior=OTHERS leaves prior_rank to it."""
    from search import SearchConfig, counterfactual_search
    from search.enumerate import combinations, singles
    from search.lockstep import rollout_lockstep
    from search.prior import SearchLog, unedited_candidate

    t0 = time.perf_counter()
    task = u.task
    gt = ground_truth(world, policy, task)
    demo = world.demonstrate(task)
    config = SearchConfig.for_world(world, max_size=2)
    result = counterfactual_search(world, policy, task.scene, demo, config=config, task=task)
    best = result.best.edit if result.best is not None else None
    prior_rank = enum_rank = n_at = None
    if gt.size is not None:
        enum_order = list(combinations(world.space, task.scene, gt.size))
        enum_rank, n_at = rank_in(enum_order, set(gt.edits)), len(enum_order)
    if gt.size is not None and (prior is not None or logs is not None):
        tried = [c for c in result.tried if c.edit.size == 1]
        every = singles(world.space, task.scene)
        if len(tried) < len(every):
            eps = world.epsilon
            tried = rollout_lockstep(world, policy, task.scene, demo, every, epsilon=eps, task=task)
        unedited = unedited_candidate(world, policy, task.scene, demo, task=task)
        if logs is not None:
            logs.append(SearchLog(task.scene, unedited, tuple(tried), gt.edits))
        if prior is not None and prior != OTHERS:
            prior_rank = prior_rank_of(world, prior, SearchLog(task.scene, unedited, (), gt.edits),
                                       tuple(tried))  # fmt: skip
    tid = task_id(task)
    row = {
        "world": world.name,
        "policy": policy_name,
        "kind": u.kind,
        "run_seed": run_seed,
        "task_seed": task.seed,
        "task_id": tid,
        "changes": "; ".join(str(c) for c in u.changes) or NONE,
        "edits_1": gt.tried[0],
        "edits_2": gt.tried[1] if len(gt.tried) > 1 else 0,
        "gt_size": gt.size or NONE,
        "gt_count": len(gt.edits),
        "gt_edits": " | ".join(str(e) for e in gt.edits) or NONE,
        "gt_objects": " ".join(sorted(gt.slots)) or NONE,
        "undo_minimal": _yes(None if u.undo is None else u.undo in gt.edits),
        "undo_restores": _yes(None if u.undo is None else u.undo in gt.restoring),
        "cf_size": result.size or NONE,
        "cf_edit": str(best) if best is not None else NONE,
        "cf_in_gt": _yes(None if best is None else best in gt.edits),
        "cf_restores": _yes(None if best is None else best in gt.restoring),
        "cf_rollouts": len(result.tried),
        "gt_rollouts": sum(gt.tried),
        "prior_rank": prior_rank or NONE,
        "enum_rank": enum_rank or NONE,
        "n_at_size": n_at or NONE,
    }
    saliency = _saliency(world, policy, task, demo, gt, methods, seed=int(tid, 16) % 2**31)
    row["seconds"] = f"{time.perf_counter() - t0:.2f}"
    assert tuple(row) == TASK_COLUMNS, "row and TASK_COLUMNS disagree"
    base = {"world": world.name, "policy": policy_name, "kind": u.kind, "task_id": tid}
    rows = [{**base, **r} for r in saliency]
    return {k: str(v) for k, v in row.items()}, [{k: str(v) for k, v in r.items()} for r in rows]


def prior_rank_of(world, prior, log, tried) -> int | None:
    """The rank of the first of `log.answer` (the minimal ground-truth edits) among the edits
    of their size, in the order of `prior`'s costs of the size-1 pass `tried`."""
    from search.enumerate import combinations

    costs = prior.costs(world.space, tried, log.unedited)
    size = log.answer[0].size
    order = list(combinations(world.space, log.scene, size, prior=costs, grouped=False))
    return rank_in(order, set(log.answer))


def cross_fitted(
    world, rows: list[dict], logs: list, *, scenes: Sequence | None = None, l2: float = 1.0
) -> list[dict]:
    """`rows` with prior_rank from priors cross-fitted over the tasks with a ground truth (one
    SearchLog each, in `rows`' order among those with gt_size): each task ranked by a prior
    fitted on every other task's log, never its own; "-" where the others give nothing to fit.
    scenes: the training scenes giving value frequencies (default: seeds 0 .. PRIOR_SCENES-1)."""
    from search.prior import fit
    from sim.core import UserError

    if scenes is None:
        scenes = [world.train_task(s).scene for s in range(PRIOR_SCENES)]
    with_gt = [i for i, r in enumerate(rows) if r["gt_size"] != NONE]
    assert len(with_gt) == len(logs), "one log per task with a ground truth"
    out = [dict(r) for r in rows]
    for j, i in enumerate(with_gt):
        try:
            prior = fit(world, logs[:j] + logs[j + 1 :], scenes, l2=l2)
        except UserError:  # no other task has a ground truth
            continue
        out[i]["prior_rank"] = str(prior_rank_of(world, prior, logs[j], logs[j].singles) or NONE)
    return out


def _saliency(world, policy, task, demo, gt: GroundTruth, methods, *, seed: int) -> list[dict]:
    """Object top-1 per method and readout against the ground truth's objects; none without a
    ground truth (nothing to name)."""
    from policy.concept_saliency import frame_maps, prepare, readouts
    from policy.saliency import check_explainable
    from sim.core import UserError

    try:
        check_explainable(policy)
    except UserError:
        return []
    if gt.size is None:
        return []
    rollout = world.rollout(task, policy)
    frames = prepare(world, task, rollout, demo)
    out = []

    def hit(groups: Sequence[tuple[str, ...]]) -> tuple[str, int]:
        if not groups:
            return NONE, 0
        return " ".join(groups[0]) or NONE, int(bool(set(groups[0]) & gt.slots))

    for method in methods:
        unsigned, signed = frame_maps(policy, frames, method, seed=seed)
        for (reading, span), ranking in readouts(frames, unsigned, signed, seed=seed).items():
            top, h = hit(ranking.groups)
            out.append({"method": method, "reading": reading, "span": span, "top": top, "hit": h})
    order = np.random.default_rng([seed, 7]).permutation(len(frames.groups))
    top, h = hit([frames.groups[int(i)] for i in order])
    out.append({"method": "random", "reading": NONE, "span": NONE, "top": top, "hit": h})
    return out


def run_world(
    world,
    policy,
    kind: str,
    n: int,
    *,
    seed: int,
    prior,
    policy_name: str,
    tries: int,
    methods: Sequence[str] = METHODS,
    on_task: Callable[[list[dict], list[dict], int], None] | None = None,
) -> tuple[list[dict], list[dict], int]:
    """n failing tasks of `kind` measured: (tasks.csv rows, saliency.csv rows, candidates
    drawn to find them); `on_task(rows, saliency rows, drawn)` after each task, all so far (with
    prior OTHERS, every task's rank from a prior cross-fitted on the other tasks so far)."""
    from search.unplanted import candidate_seed, failing

    rows, sal = [], []
    logs: list | None = [] if prior == OTHERS else None
    scenes = [world.train_task(s).scene for s in range(PRIOR_SCENES)] if logs is not None else []
    last = candidate_seed(seed, 0) - 1
    for u in failing(world, policy, kind, n, seed=seed, tries=tries):
        row, srows = measure(
            world, policy, u, prior=prior, policy_name=policy_name, run_seed=seed,
            methods=methods, logs=logs,
        )  # fmt: skip
        rows.append(row)
        sal += srows
        last = u.task.seed
        if logs is not None:  # every task so far ranked by a prior fitted on the others
            rows = cross_fitted(world, rows, logs, scenes=scenes)
        if on_task is not None:
            on_task(rows, sal, last - candidate_seed(seed, 0) + 1)
    return rows, sal, last - candidate_seed(seed, 0) + 1
