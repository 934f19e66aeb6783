"""The search on a world whose counterfactual "succeeds" (World.counterfactual: the MuJoCo
worlds, every candidate rolled out to the end and judged by the task's R'), timed in one
process against the larger of two bounds measured in the same run, and against the naive loop.

The forward-pass bound (dfa_viz.bench.bound) is the policy's forward passes over the very
batches the search ran; the MuJoCo bound (dfa_viz.bench.physics) is the world's step_batch and
render_batch calls the search made, recorded and replayed alone. A MuJoCo search renders,
steps and runs the policy one after the other, so no search that rolls these candidates out
can take less than the larger of the two; its ratio to it is what the rest adds. The naive loop
rolls one candidate at a time (dfa_viz.bench.search.naive_search): on NAIVE_SAMPLE of the
edits, evenly spread, its time per candidate extrapolated (a batch-1 forward pass costs nearly
as much as a batch of 22), its verdicts checked against the search's.

Size 1 is every single edit of the task's scene (one lockstep pass, as the search rolls them);
size 2 the first `pairs` size-2 edits in the search's order (ascending summed first-step
distance of their single changes, presence edits first), one lockstep pass: the whole size-2
space of a MuJoCo world takes too long to roll out for a benchmark.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from dfa_viz.bench.bound import forward_bound_s, step_batches
from dfa_viz.bench.physics import physics_bound_s, recorded
from dfa_viz.bench.search import naive_search
from dfa_viz.bench.timing import best_of
from policy import Policy, base_policy
from search import combinations, rollout_lockstep, singles
from search.lockstep import compared_steps
from sim import get_world
from sim.core import Change, Edit, Task, Trajectory, UserError, World

MAX_TO_BOUND = 2.0  # the target: the search within 2x of the larger of its bounds
PAIRS = 32  # size-2 edits measured, the first in the search's order
NAIVE_SAMPLE = 8  # edits of each size rolled out by the naive loop


def first_step_prior(
    world: World, policy: Policy, task: Task, demo: Trajectory, edits: list[Edit]
) -> dict[Change, float]:
    """Each single change's first-step action distance (what the search's size-1 pass gives
    search.combinations to order size-2 edits by): one batched render and forward pass."""
    out = policy.outputs(world.render_batch(world.apply_batch(task.scene, edits)))
    dist = np.abs(out - demo.actions[0][None]).sum(axis=1)
    return {next(iter(e.changes)): float(d) for e, d in zip(edits, dist, strict=True)}


def bench_edits(
    world: World,
    policy: Policy,
    task: Task,
    demo: Trajectory,
    edits: list[Edit],
    *,
    repeats: int,
    naive_sample: int,
) -> dict:
    """The search's lockstep pass over `edits` (the best of `repeats`, its world calls
    recorded), then in the same process its MuJoCo bound, its forward-pass bound and the naive
    loop on `naive_sample` of the edits, evenly spread (one run: it is the slowest)."""
    eps = world.epsilon

    def search():
        with recorded(world) as calls:
            cands = rollout_lockstep(world, policy, task.scene, demo, edits, epsilon=eps, task=task)
        return cands, calls

    search_s, (tried, calls) = best_of(search, repeats)
    physics_s = physics_bound_s(world, calls, repeats)
    frames = world.render_batch(world.apply_batch(task.scene, edits))  # (N, H, W, 3)
    batches = step_batches([tried])
    forward_s = forward_bound_s(policy, frames, batches, repeats)
    at = sorted({int(i) for i in np.linspace(0, len(edits) - 1, min(naive_sample, len(edits)))})
    sample = [edits[i] for i in at]
    naive_s, naive = best_of(
        lambda: naive_search(world, policy, task.scene, demo, sample, eps, task=task), 1
    )
    bound_s = max(physics_s, forward_s)
    per_candidate = search_s / len(edits)
    return {
        "edits": len(edits),
        "steps": compared_steps(world, demo),
        "valid": sum(c.valid for c in tried),
        "search_s": search_s,
        "evaluated": int(sum(batches)),
        "forward_s": forward_s,
        "stepped": calls.stepped,
        "rendered": calls.rendered,
        "physics_s": physics_s,
        "bound_s": bound_s,
        "to_bound": search_s / bound_s,
        "to_forward": search_s / forward_s,
        "to_physics": search_s / physics_s,
        "naive_sampled": len(sample),
        "naive_per_candidate_s": naive_s / len(sample),
        "search_per_candidate_s": per_candidate,
        "naive_ratio": naive_s / len(sample) / per_candidate,
        "agree": sum(v == tried[i].valid for v, i in zip(naive, at, strict=True)),  # type: ignore[arg-type]
        "naive_valid": sum(naive),  # type: ignore[arg-type]
    }


def bench_closed_loop(
    name: str,
    *,
    shift: str = "object_ti",
    seed: int = 0,
    singles_at: Sequence[int] | None = None,
    pairs: int = PAIRS,
    repeats: int = 1,
    naive_sample: int = NAIVE_SAMPLE,
    policy: Policy | None = None,
) -> dict:
    """Size 1 (every single edit, or those at `singles_at` in the search's order) and size 2
    (the first `pairs` in the search's order) of the search on the test task of `shift` and
    `seed`, each against its bounds and the naive loop (bench_edits): {"task": its name,
    1: figures, 2: figures}. `policy`: the world's base policy already loaded (tests)."""
    world = get_world(name)
    if world.counterfactual != "succeeds":
        raise UserError(f"{name}: its counterfactual follows the demonstration (bench.search)")
    policy = policy or base_policy(world)
    task = world.test_task(shift, seed)
    demo = world.demonstrate(task)
    ones = singles(world.space, task.scene)
    prior = first_step_prior(world, policy, task, demo, ones)  # also warms GL and the policy
    twos = list(itertools.islice(combinations(world.space, task.scene, 2, prior=prior), pairs))
    picked = ones if singles_at is None else [ones[i] for i in singles_at]
    kw = {"repeats": repeats, "naive_sample": naive_sample}
    return {
        "task": f"{shift} seed {seed}",
        1: bench_edits(world, policy, task, demo, picked, **kw),  # type: ignore[arg-type]
        2: bench_edits(world, policy, task, demo, twos, **kw),  # type: ignore[arg-type]
    }


def closed_loop_rows(name: str, r: dict) -> list[tuple[str, str, str, bool | None]]:
    """bench_closed_loop's figures as (what, value, target, met) rows: per size the search
    against the larger of its bounds (target <= MAX_TO_BOUND), then against the naive loop."""
    rows: list[tuple[str, str, str, bool | None]] = []
    for size in (1, 2):
        f = r[size]
        which = "every single edit" if size == 1 else "the first size-2 edits in its order"
        what = (
            f"{name}: size-{size} search on {r['task']}, {which} ({f['edits']} edits rolled out "
            f"{f['steps']} steps, {f['valid']} valid: {f['search_s']:.2f} s) vs the larger of "
            f"its forward-pass bound ({f['evaluated']} candidate-steps through the policy: "
            f"{f['forward_s']:.2f} s, {f['to_forward']:.2f}x) and its MuJoCo bound "
            f"({f['stepped']} scenes stepped and {f['rendered']} frames rendered as the search "
            f"did, timed alone: {f['physics_s']:.2f} s, {f['to_physics']:.2f}x)"
        )
        ok = f["to_bound"] <= MAX_TO_BOUND
        rows.append((what, f"{f['to_bound']:.2f}x", f"<= {MAX_TO_BOUND:g}x", ok))
        rows.append(
            (
                f"{name}: the same size-{size} search vs the naive loop, one candidate at a "
                "time (a render, a batch-1 forward and the environment's step of one scene per "
                f"step: {f['naive_per_candidate_s']:.2f} s per candidate, {f['naive_sampled']} "
                f"timed and extrapolated, the search's verdict on {f['agree']} of them; the "
                f"search {f['search_per_candidate_s']:.2f} s)",
                f"{f['naive_ratio']:.2f}x",
                "",
                None,
            )
        )
    return rows
