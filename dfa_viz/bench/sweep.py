"""`dfa sweep`'s speed: every single edit over 100 training tasks, against the forward-pass
bound (the frames the sweep put through the policy, at the policy's batched throughput
measured in the same run) and, on worlds whose rollouts are simulated (World.simulated),
against the larger of that and the physics bound (the world's steps and renders the sweep
made, timed alone: dfa_viz.bench.physics). All are timed warm, the best of `repeats` (the
bound's forward pass runs once before its clock starts; the sweep's first run pays the
imports and the policy's first batches).

Where a world's sweep is measured on more than one backend, its rollouts per second per core:
in one process against its forward-pass bound's, on 2 worker processes and on Ray against one
process's, all measured in the same run (1.0x: every core as fast as the one process)."""

from __future__ import annotations

import contextlib
import time

from dfa_viz.bench.timing import best_of

Run = tuple[str, int]  # (backend, workers): ("local", 1) is in this process
# world -> (tasks, the target in seconds on 2 cores, or None, the runs measured)
SWEPT: dict[str, tuple[int, float | None, tuple[Run, ...]]] = {
    "nav2d": (100, 10.0, (("local", 1),)),
    "doorkey": (100, None, (("local", 1),)),
    "tabletop": (100, 120.0, (("local", 1), ("local", 2), ("ray", 2))),
}
MAX_TO_BOUND = 3.0  # every sweep within 3x of its bound
BATCH = 512  # the sweep's rollouts per unit: the batch its forward passes see


def bench_sweep(
    name: str,
    *,
    tasks: int = 100,
    workers: int = 1,
    repeats: int = 1,
    backend: str = "local",
    physics_s: float | None = None,
) -> dict:
    """Wall time of the whole single-edit sweep over `tasks` training tasks (policy loaded,
    one torch thread per worker: here with one worker, else a process pool, or on Ray a local
    instance with `workers` CPUs, started before the clock and kept over the repeats), and the
    forward-pass bound of the frames it evaluated; with `physics_s` (the physics bound in one
    process: dfa_viz.bench.physics), its ratio to the larger of the two bounds per worker."""
    from dfa_viz.backends import one_torch_thread, ray_instance
    from dfa_viz.checked_policy import checked_policy
    from dfa_viz.sweep.run import SweepJob, backend_runner
    from search.sweep import sweep, sweep_tasks
    from sim import get_world

    world = get_world(name)
    policy = checked_policy(name, None)
    todo = sweep_tasks(world, tasks)
    runner = backend_runner(SweepJob(name), workers=workers, backend=backend)
    with contextlib.ExitStack() as stack:
        if backend == "ray":
            stack.enter_context(ray_instance(workers))
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
    physics = None if physics_s is None else physics_s / workers
    return {
        "wall_s": wall_s,
        "tasks": tasks,
        "distinct": result.distinct,  # type: ignore[attr-defined]
        "cells": len(result.cells),  # type: ignore[attr-defined]
        "rollouts": result.rollouts,  # type: ignore[attr-defined]
        "frames": result.frames,  # type: ignore[attr-defined]
        "forward_per_s": per_s,
        "bound_s": bound_s,
        "to_forward": wall_s / bound_s,
        "physics_s": physics,
        "to_bound": wall_s / max(bound_s, physics or 0.0),
        "workers": workers,
        "backend": backend,
        "per_core_s": result.rollouts / wall_s / workers,  # type: ignore[attr-defined]
        "bound_per_core_s": result.rollouts / (bound_s * workers),  # type: ignore[attr-defined]
    }


def sweep_rows(name: str, *, repeats: int = 1) -> list[tuple[str, str, str, bool | None]]:
    """(what, value, target, met) for each run measured, the best of `repeats`, each against
    its bound (on a simulated world, World.simulated, the larger of the forward-pass and physics
    bounds, the physics bound measured once in this process); with more than one run, then
    the rollouts per second per core of each (per_core_rows)."""
    from dfa_viz.bench.physics import bench_physics
    from sim import get_world

    tasks, target, runs = SWEPT[name]
    simulated = get_world(name).simulated
    physics = bench_physics(name, tasks=tasks, repeats=repeats) if simulated else None
    rows = []
    measured = []
    for backend, workers in runs:
        r = bench_sweep(
            name,
            tasks=tasks,
            workers=workers,
            repeats=repeats,
            backend=backend,
            physics_s=None if physics is None else physics["physics_s"],
        )
        measured.append(r)
        rows.append(
            (
                f"{name}: `dfa sweep`, every single edit over {r['tasks']} training tasks "
                f"({r['distinct']} distinct, {r['cells']} edits, {r['rollouts']} rollouts) "
                f"{_where(r)}",
                f"{r['wall_s']:.1f} s",
                "" if target is None else f"<= {target:g} s",
                None if target is None else r["wall_s"] <= target,
            )
        )
        rows.append(bound_row(name, r, physics))
    return rows + (per_core_rows(name, measured) if len(measured) > 1 else [])


def bound_row(name: str, r: dict, physics: dict | None) -> tuple[str, str, str, bool | None]:
    """The sweep `r` against its bound: the forward-pass bound, or with `physics` (what
    dfa_viz.bench.physics.bench_physics gives) the larger of it and the physics bound."""
    forward = (
        f"{r['frames']} frames at {r['forward_per_s']:.0f} frames/s through the policy per "
        f"worker: {r['bound_s']:.2f} s"
    )
    if physics is None:
        what = f"{name}: the same sweep vs its forward-pass bound ({forward})"
    else:
        what = (
            f"{name}: the same sweep vs the larger of its forward-pass bound ({forward}) and "
            f"its physics bound ({physics['stepped']} scenes stepped and "
            f"{physics['rendered']} frames rendered by the world as the sweep did, timed "
            f"alone: {r['physics_s']:.2f} s per worker; {r['to_forward']:.1f}x the "
            "forward-pass bound)"
        )
    ratio = r["to_bound"]
    return (what, f"{ratio:.1f}x", f"<= {MAX_TO_BOUND:g}x", ratio <= MAX_TO_BOUND)


def _where(r: dict) -> str:
    if r["backend"] == "ray":
        return f"on Ray ({r['workers']} CPUs of a local instance)"
    return "in one process" if r["workers"] == 1 else f"on {r['workers']} worker processes"


def per_core_rows(name: str, measured: list[dict]) -> list[tuple[str, str, str, bool | None]]:
    """The sweep's rollouts per second per core of each run: the first (one process) against
    its forward-pass bound's, the others against the first's."""
    one = measured[0]
    rows: list[tuple[str, str, str, bool | None]] = [
        (
            f"{name}: sweep rollouts per second per core {_where(one)}: {one['per_core_s']:.0f}"
            f"/s vs its forward-pass bound's {one['bound_per_core_s']:.0f}/s",
            f"{one['per_core_s'] / one['bound_per_core_s']:.3f}x",
            "",
            None,
        )
    ]
    for r in measured[1:]:
        rows.append(
            (
                f"{name}: sweep rollouts per second per core {_where(r)}: "
                f"{r['per_core_s']:.0f}/s vs {one['per_core_s']:.0f}/s in one process",
                f"{r['per_core_s'] / one['per_core_s']:.2f}x",
                "",
                None,
            )
        )
    return rows
