"""The tabletop search on an `other` task (no counterfactual: every edit is tried), with frames
composited from cached top views and with MuJoCo drawing every frame, each against the
forward-pass bound measured in the same run, and against a naive loop that edits the scene in
place, renders it once and runs a batch-1 forward per candidate.
"""

from __future__ import annotations

import functools
import time

import numpy as np

from dfa_viz.bench.bound import forward_bound_s, step_batches, waves
from policy import Policy, failing_test_task
from search import SearchConfig, combinations, counterfactual_search, rollout_lockstep, singles
from sim.core import Edit, Scene, Trajectory

TARGETS = {"all_s": 2.0, "to_bound": 2.0}
NAIVE_SAMPLE = 200  # naive candidates timed; the per-candidate time is extrapolated from them


def naive_candidate(world, policy: Policy, scene: Scene, demo: Trajectory, edit: Edit) -> bool:
    """One candidate the naive way: the edit made in the one model in place, one render, a
    batch-1 forward. True when the edit is valid (horizon 1: one compared step)."""
    frame = world.render(world.apply(scene, edit))[None]  # (1, 80, 80, 3)
    out = policy.outputs(frame)  # (1, 4)
    return float(np.abs(out[0] - demo.actions[0]).sum()) < world.epsilon


def naive(
    world, policy: Policy, scene: Scene, demo: Trajectory, edits: list[Edit]
) -> tuple[float, list[bool]]:
    """naive_candidate over `edits`: (seconds per candidate, validity)."""
    t0 = time.perf_counter()
    valid = [naive_candidate(world, policy, scene, demo, e) for e in edits]
    return (time.perf_counter() - t0) / len(edits), valid


def _paired(fn, bound, repeats: int) -> tuple[float, float, list[float], object]:
    """Run fn `repeats` times, its forward-pass bound(output) measured right after each run.
    Returns (best seconds, median of time / bound over the runs, the bounds, last output):
    on a machine shared with other work the ratio compares like with like."""
    times, bounds, out = [], [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
        bounds.append(bound(out))
    ratio = float(np.median([t / b for t, b in zip(times, bounds, strict=True)]))
    return min(times), ratio, bounds, out


def _steps(cands) -> int:
    """Candidate-steps a rollout evaluated."""
    return int(sum(np.isfinite(c.distances).sum() for c in cands))


def _cold(comp, fn):
    """fn with nothing drawn before: the views in memory and on disk ignored."""

    def run():
        comp.clear()
        store, comp.store = comp.store, None
        try:
            return fn()
        finally:
            comp.store = store

    return run


def _stored(comp, fn):
    """fn as a later process starts it: the views read from disk."""

    def run():
        comp.reopen()
        return fn()

    return run


def _agree(everything: list[Edit], result, mj_all, cands, mj, naive_valid: dict) -> None:
    """The composited search tried every edit and agrees with MuJoCo's (every distance) and
    with the naive loop (every sampled verdict)."""
    tried = [c.edit for c in result.tried]
    assert sorted(map(str, tried)) == sorted(map(str, everything)), "the search missed edits"
    same = [c.edit for c in mj_all.tried] == tried and all(
        np.array_equal(a.distances, b.distances, equal_nan=True)
        for a, b in zip(mj_all.tried, result.tried, strict=True)
    )
    assert same and [c.distances[0] for c in mj] == [c.distances[0] for c in cands]
    by_edit = {c.edit: c.valid for c in result.tried}
    bad = [e for e, ok in naive_valid.items() if ok != by_edit[e]]
    assert not bad, "naive and batched candidates disagree"


def bench_other(
    world, policy: Policy, *, repeats: int = 3, seed: int = 0, max_size: int = 2
) -> dict:
    """Time the tabletop search on the first failing `other` task of `seed` (seconds).

    singles_*: every single edit rolled out in lockstep; all_*: counterfactual_search up to
    `max_size` (no counterfactual: every edit tried). *_cold: no view drawn before (in memory
    or on disk), as on a machine's first run; *_stored: the views read from disk first, as in
    every later process; *_warm: the views of the run before kept in memory; *_mujoco: MuJoCo
    draws every frame.
    *_s: the best of `repeats` runs (MuJoCo's whole search: one run). *_to_bound: the median
    over the runs of time / bound, the bound measured right after each run: the policy's
    forward passes over the batches the search ran (dfa_viz.bench.bound).
    naive_per_candidate_s: in-place edit, one MuJoCo render, a batch-1 forward, over
    NAIVE_SAMPLE candidates spread over all of them (best of `repeats`).
    """
    task, _ = failing_test_task(world, policy, "other", seed)
    demo = world.demonstrate(task)
    scene, eps = task.scene, world.epsilon
    config = SearchConfig.for_world(world, max_size=max_size)
    one = singles(world.space, scene)
    everything = [e for k in range(1, max_size + 1) for e in combinations(world.space, scene, k)]
    frames = world.render_batch([world.apply(scene, e) for e in everything])  # (N, 80, 80, 3)
    comp = world._compositor
    cold, stored = functools.partial(_cold, comp), functools.partial(_stored, comp)

    def run_singles():
        return rollout_lockstep(world, policy, scene, demo, one, epsilon=eps)

    def run_all():
        return counterfactual_search(world, policy, scene, demo, config=config)

    def singles_bound(cands) -> float:
        return forward_bound_s(policy, frames, step_batches([cands]), 3)

    def all_bound(result) -> float:
        return forward_bound_s(policy, frames, step_batches(waves(result.tried, config.wave)), 1)

    run_singles()  # warm: the policy at this batch size
    r: dict = {"singles": len(one), "all": len(everything), "max_size": max_size}
    bounds: dict[str, list[float]] = {"singles": [], "all": []}

    def measure(k: str, how: str, fn, n: int):
        bound = singles_bound if k == "singles" else all_bound
        r[f"{k}_{how}_s"], r[f"{k}_{how}_to_bound"], b, out = _paired(fn, bound, n)
        bounds[k] += b
        return out

    cands = measure("singles", "cold", cold(run_singles), repeats)
    comp.clear()
    run_singles()  # their views drawn and written to disk
    measure("singles", "stored", stored(run_singles), repeats)
    measure("singles", "warm", run_singles, repeats)
    drawn, fell, groups = comp.drawn, comp.fell_back, comp.groups_drawn
    result = measure("all", "cold", cold(run_all), repeats)
    assert not result.found and result.complete, result.summary()
    r["views_drawn"] = (comp.drawn - drawn) // repeats
    r["drawn_whole"] = (comp.fell_back - fell) // repeats
    r["groups_drawn"] = (comp.groups_drawn - groups) // repeats
    comp.clear()
    run_all()  # every view drawn and written to disk
    measure("all", "stored", stored(run_all), repeats)
    measure("all", "warm", run_all, repeats)
    world.compositing = False
    try:
        mj = measure("singles", "mujoco", run_singles, repeats)
        mj_all = measure("all", "mujoco", run_all, 1)
        picks = np.linspace(0, len(everything) - 1, min(NAIVE_SAMPLE, len(everything)), dtype=int)
        sample = [everything[i] for i in picks]
        policy.outputs(frames[:1])  # warm: batch-1 kernels
        # best of the repeats: a batch-1 forward is the figure most at the mercy of other load
        r["naive_per_candidate_s"], naive_valid = min(
            (naive(world, policy, scene, demo, sample) for _ in range(repeats)),
            key=lambda t: t[0],
        )
        r["naive_sampled"] = len(sample)
    finally:
        world.compositing = True
    _agree(everything, result, mj_all, cands, mj, dict(zip(sample, naive_valid, strict=True)))
    for k in ("singles", "all"):
        r[f"{k}_bound_s"] = float(np.median(bounds[k]))
    r["forward_per_s"] = _steps(result.tried) / r["all_bound_s"]
    r["naive_ratio"] = r["naive_per_candidate_s"] / (r["all_stored_s"] / len(everything))
    return r


def compositing_rows(r: dict) -> list[tuple[str, str, str, bool | None]]:
    """bench_other's figures as (what, value, target, met) rows: ratios to the bound.

    The targets are judged on the views read from disk (every run but a machine's first); the
    time with nothing drawn before is in the same row."""
    rows: list[tuple[str, str, str, bool | None]] = []
    up_to = f"every edit up to size {r['max_size']}"
    modes = (
        ("cold", "nothing drawn before"),
        ("stored", "views read from disk"),
        ("warm", "warm"),
        ("mujoco", "MuJoCo"),
    )
    for k, what in (("singles", "every single edit"), ("all", up_to)):
        n, bound = r[k], r[f"{k}_bound_s"]
        times = ", ".join(f"{how} {r[f'{k}_{m}_s'] * 1e3:.0f} ms" for m, how in modes)
        rows.append(
            (
                f"{what} on `other` ({n} edits), composited frames (views from disk) vs its "
                f"forward-pass bound ({bound * 1e3:.0f} ms at {r['forward_per_s']:.0f} frames/s); "
                f"{times}; MuJoCo {r[f'{k}_mujoco_to_bound']:.1f}x the bound",
                f"{r[f'{k}_stored_to_bound']:.2f}x",
                f"<= {TARGETS['to_bound']:.0f}x",
                r[f"{k}_stored_to_bound"] <= TARGETS["to_bound"],
            )
        )
    rows.append(
        (
            f"{up_to} on `other` ({r['all']} edits; MuJoCo drew {r['groups_drawn']} groups of "
            f"touching objects and {r['drawn_whole']} whole scenes off the pixel grid), "
            f"composited, views read from disk (nothing drawn before: {r['all_cold_s']:.2f} s, "
            f"{r['views_drawn']} top views drawn)",
            f"{r['all_stored_s']:.2f} s",
            f"<= {TARGETS['all_s']:.0f} s",
            r["all_stored_s"] <= TARGETS["all_s"],
        )
    )
    rows.append(
        (
            f"the same, composited vs MuJoCo rendering every frame ({r['all_mujoco_s']:.2f} s)",
            f"{r['all_mujoco_s'] / r['all_stored_s']:.1f}x",
            "",
            None,
        )
    )
    rows.append(
        (
            f"batched, composited ({r['all_stored_s'] / r['all'] * 1e3:.3f} ms per candidate) vs "
            "naive: in-place edit, one MuJoCo render and a batch-1 forward per candidate "
            f"({r['naive_per_candidate_s'] * 1e3:.2f} ms, {r['naive_sampled']} timed)",
            f"{r['naive_ratio']:.0f}x",
            "",
            None,
        )
    )
    return rows
