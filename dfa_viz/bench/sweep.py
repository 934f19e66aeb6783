"""`dfa sweep`'s speed: every single edit over 100 training tasks, against the forward-pass
bound (the frames the sweep put through the policy, at the policy's batched throughput
measured in the same run). Both are timed warm, the best of `repeats` (the bound's forward
pass runs once before its clock starts; the sweep's first run pays the imports and the
policy's first batches)."""

from __future__ import annotations

import time

from dfa_viz.bench.timing import best_of

# world -> (tasks, the target in seconds on 2 cores, or None, workers measured)
SWEPT: dict[str, tuple[int, float | None, tuple[int, ...]]] = {
    "nav2d": (100, 10.0, (1,)),
    "doorkey": (100, None, (1,)),
    "tabletop": (100, 120.0, (1, 2)),
}
BATCH = 512  # the sweep's rollouts per unit: the batch its forward passes see


def bench_sweep(name: str, *, tasks: int = 100, workers: int = 1, repeats: int = 1) -> dict:
    """Wall time of the whole single-edit sweep over `tasks` training tasks (policy loaded,
    one torch thread per worker: here with one worker, else a process pool), and the
    forward-pass bound of the frames it evaluated."""
    from dfa_viz.backends import one_torch_thread
    from dfa_viz.checked_policy import checked_policy
    from dfa_viz.sweep.run import SweepJob, backend_runner
    from search.sweep import sweep, sweep_tasks
    from sim import get_world

    world = get_world(name)
    policy = checked_policy(name, None)
    todo = sweep_tasks(world, tasks)
    runner = backend_runner(SweepJob(name), workers=workers)
    wall_s, result = best_of(lambda: sweep(world, policy, todo, runner=runner), repeats)
    scenes = [t.scene for t in todo[:1]] * BATCH
    frames = world.render_batch(scenes)  # (BATCH, H, W, 3)
    with one_torch_thread():
        policy.outputs(frames)
        t0 = time.perf_counter()
        policy.outputs(frames)
        forward_s = time.perf_counter() - t0
    per_s = BATCH / forward_s
    bound_s = result.frames / per_s / workers  # type: ignore[attr-defined]
    return {
        "wall_s": wall_s,
        "tasks": tasks,
        "distinct": result.distinct,  # type: ignore[attr-defined]
        "cells": len(result.cells),  # type: ignore[attr-defined]
        "rollouts": result.rollouts,  # type: ignore[attr-defined]
        "frames": result.frames,  # type: ignore[attr-defined]
        "forward_per_s": per_s,
        "bound_s": bound_s,
        "to_bound": wall_s / bound_s,
        "workers": workers,
    }


def sweep_rows(name: str, *, repeats: int = 1) -> list[tuple[str, str, str, bool | None]]:
    """(what, value, target, met) for each worker count measured, the best of `repeats`."""
    tasks, target, counts = SWEPT[name]
    rows = []
    for workers in counts:
        r = bench_sweep(name, tasks=tasks, workers=workers, repeats=repeats)
        who = "in one process" if workers == 1 else f"on {workers} worker processes"
        rows.append(
            (
                f"{name}: `dfa sweep`, every single edit over {r['tasks']} training tasks "
                f"({r['distinct']} distinct, {r['cells']} edits, {r['rollouts']} rollouts) {who}",
                f"{r['wall_s']:.1f} s",
                "" if target is None else f"<= {target:g} s",
                None if target is None else r["wall_s"] <= target,
            )
        )
        rows.append(
            (
                f"{name}: the same sweep vs its forward-pass bound ({r['frames']} frames at "
                f"{r['forward_per_s']:.0f} frames/s through the policy per worker: "
                f"{r['bound_s']:.2f} s)",
                f"{r['to_bound']:.1f}x",
                "",
                None,
            )
        )
    return rows
