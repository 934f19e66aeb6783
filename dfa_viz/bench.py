"""`dfa bench`: the search against a naive one-candidate loop, and a full run, timed here."""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from policy import Policy, base_policy, failing_test_task
from policy.model import probabilities
from search import Candidate, combinations, rollout_lockstep
from search.lockstep import compared_steps
from sim import get_world
from sim.core import Edit, Scene, Trajectory, World


def naive_search(
    world: World, policy: Policy, scene: Scene, demo: Trajectory, edits: list[Edit], epsilon: float
) -> list[bool]:
    """The baseline: one candidate at a time, a batch-1 render and forward per step."""
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


def _best_of(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench_world(name: str, *, repeats: int = 3, shift: str = "distractor_ti") -> dict:
    """Time the whole size-1 + size-2 search (every edit of both sizes, no early stop),
    batched in lockstep and naive, on one failing task of `shift`."""
    world = get_world(name)
    policy = base_policy(world)
    task, _ = failing_test_task(world, policy, shift, 0)
    demo = world.demonstrate(task)
    edits = {k: list(combinations(world.space, task.scene, k)) for k in (1, 2)}
    everything = edits[1] + edits[2]
    eps = world.epsilon

    def batched() -> list[Candidate]:
        return [
            c
            for k in (1, 2)
            for c in rollout_lockstep(world, policy, task.scene, demo, edits[k], epsilon=eps)
        ]

    t_batched, tried = _best_of(batched, repeats)
    t_naive, naive_valid = _best_of(
        lambda: naive_search(world, policy, task.scene, demo, everything, eps), 1
    )
    assert naive_valid == [c.valid for c in tried], "naive and batched searches disagree"
    return {
        "candidates": len(everything),
        "size1": len(edits[1]),
        "size2": len(edits[2]),
        "batched_s": t_batched,
        "naive_s": t_naive,
        "per_s": len(everything) / t_batched,
        "ratio": t_naive / t_batched,
    }


def bench_run(name: str, shift: str = "object_ti", seed: int = 0) -> float:
    """Wall time of a whole `dfa run` in this process, base policy already cached."""
    from dfa_viz.session import run_once

    base_policy(get_world(name))  # make sure it is cached
    t0 = time.perf_counter()
    run_once(name, shift, seed, out=Path("recordings") / "bench", progress=False)
    return time.perf_counter() - t0


def run_bench(worlds: tuple[str, ...], *, repeats: int = 3) -> list[dict]:
    console = Console()
    table = Table(
        title=f"dfa bench — {platform.processor() or platform.machine()}, "
        f"{platform.python_version()}"
    )
    for col in (
        "world",
        "candidates (size 1 + 2)",
        "search s",
        "candidates/s",
        "naive s",
        "batched / naive",
        "dfa run s",
    ):
        table.add_column(col, justify="right")
    rows = []
    for name in worlds:
        r = bench_world(name, repeats=repeats)
        r["run_s"] = bench_run(name)
        r["world"] = name
        rows.append(r)
        table.add_row(
            name,
            f"{r['candidates']} ({r['size1']} + {r['size2']})",
            f"{r['batched_s']:.3f}",
            f"{r['per_s']:.0f}",
            f"{r['naive_s']:.3f}",
            f"{r['ratio']:.1f}x",
            f"{r['run_s']:.1f}",
        )
    console.print(table)
    return rows
