"""The search against a naive one-candidate loop and against the forward-pass bound, timed in
the same process."""

from __future__ import annotations

import numpy as np

from dfa_viz.bench.bound import MIN_S, forward_bound_s, step_batches
from dfa_viz.bench.timing import best_of
from policy import Policy, base_policy, failing_test_task
from policy.model import probabilities
from search import Candidate, combinations, rollout_lockstep
from search.lockstep import compared_steps
from sim import get_world
from sim.core import Edit, Scene, Task, Trajectory, World


def naive_search(
    world: World,
    policy: Policy,
    scene: Scene,
    demo: Trajectory,
    edits: list[Edit],
    epsilon: float,
    task: Task | None = None,
) -> list[bool]:
    """The baseline: one candidate at a time, a batch-1 render and forward per step, each
    judged as the world's counterfactual is (World.counterfactual, search.lockstep): "follows"
    drops a candidate the first step its action leaves the demonstration's; "succeeds" rolls
    each out as far as the search does and asks R' of `task` (default: `world.task_for(scene)`)
    of its states (world.success)."""
    if world.counterfactual == "succeeds":
        task = task or world.task_for(scene)
        return [
            naive_rollout_succeeds(world, policy, world.apply(scene, e), demo, task) for e in edits
        ]
    valid = []
    steps = compared_steps(world, demo)
    for edit in edits:
        s, ok = world.apply(scene, edit), True
        for t in range(steps):
            out = policy.outputs(world.render(s)[None])  # (1, A)
            if world.discrete:
                a = out.argmax(axis=1)
                probabilities(out)
                ok = int(a[0]) == int(demo.actions[t])
            else:
                a = out
                ok = float(np.abs(out[0] - demo.actions[t]).sum()) < epsilon
            if not ok:
                break
            if t + 1 < steps:
                s = world.step_batch([s], a)[0]
        valid.append(ok)
    return valid


def naive_rollout_succeeds(
    world: World, policy: Policy, scene: Scene, demo: Trajectory, task: Task
) -> bool:
    """One edited scene rolled out alone (a render, a batch-1 forward and the world's step of
    one scene per step, as many steps as rollout_lockstep takes), judged by R' of `task`."""
    scenes = [scene]
    for _ in range(compared_steps(world, demo)):
        out = policy.outputs(world.render(scenes[-1])[None])  # (1, A)
        a = out.argmax(axis=1) if world.discrete else out
        scenes.append(world.step_batch([scenes[-1]], a)[0])
    return world.success(task, scenes)


def bench_world(
    name: str,
    *,
    repeats: int = 3,
    shift: str = "distractor_ti",
    sizes: tuple[int, ...] = (1, 2),
    policy: str | None = None,
) -> dict:
    """Time the whole search over `sizes` (every edit of each size, no early stop), batched in
    lockstep and naive, on one failing task of `shift`; and its forward-pass bound
    (dfa_viz.bench.bound: the policy's forward passes over the batches the search ran).
    `policy`: a policy spec (policy.outside) instead of the base policy."""
    from policy.outside import load

    world = get_world(name)
    policy = base_policy(world) if policy is None else load(policy, world)
    task, _ = failing_test_task(world, policy, shift, 0)
    demo = world.demonstrate(task)
    edits = {k: list(combinations(world.space, task.scene, k)) for k in sizes}
    everything = [e for k in sizes for e in edits[k]]
    eps = world.epsilon

    def batched() -> list[Candidate]:  # as the search does for small spaces: one pass
        return rollout_lockstep(world, policy, task.scene, demo, everything, epsilon=eps)

    t_batched, tried = best_of(batched, repeats, min_s=MIN_S)  # timed as its bound is
    t_naive, naive_valid = best_of(
        lambda: naive_search(world, policy, task.scene, demo, everything, eps), 1
    )
    assert naive_valid == [c.valid for c in tried], "naive and batched searches disagree"
    evaluated = int(sum(np.isfinite(c.distances).sum() for c in tried))  # candidate-steps
    frames = world.render_batch([world.apply(task.scene, e) for e in everything])  # (N, H, W, 3)
    batches = step_batches([tried])
    bound = forward_bound_s(policy, frames, batches, max(repeats, 5))
    return {
        "evaluated": evaluated,
        "passes": len(batches),
        "forward_per_s": evaluated / bound,
        "bound_s": bound,
        "to_bound": t_batched / bound,
        "candidates": len(everything),
        "per_size": {k: len(v) for k, v in edits.items()},
        "batched_s": t_batched,
        "naive_s": t_naive,
        "per_s": len(everything) / t_batched,
        "ratio": t_naive / t_batched,
    }
