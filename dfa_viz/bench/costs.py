"""`dfa bench`: what a world costs beyond its search — rendering, finetuning, recording, and one
run of the finetuning experiment."""

from __future__ import annotations

import time
from pathlib import Path

from dfa_viz.bench.timing import best_of
from policy import base_policy, failing_test_task, finetune, training_demos
from sim import get_world

Row = tuple[str, str, str, bool | None]  # (what, value, target, met)


def render_throughput(name: str, *, n: int = 64, repeats: int = 3) -> dict[str, float]:
    """Frames per second of one batched render of n scenes vs n one-scene renders."""
    world = get_world(name)
    task = world.test_task("distractor_ti", 0)
    scenes = [t.scene for t in world.fresh_tasks(task, n, seed=0, layouts="train")]
    batched, _ = best_of(lambda: world.render_batch(scenes), repeats)
    single, _ = best_of(lambda: [world.render_batch([s]) for s in scenes], repeats)
    return {"n": n, "batched_fps": n / batched, "single_fps": n / single, "ratio": single / batched}


def finetune_cost(name: str, *, budget: int = 25) -> dict[str, float]:
    """Wall time of one default finetuning (the experiment's: `budget` trajectories, half of
    every batch replayed from the training demonstrations)."""
    from policy.train import FINETUNE, TrainConfig

    world = get_world(name)
    policy = base_policy(world)
    task, _ = failing_test_task(world, policy, "object_ti", 0)
    demos = [world.demonstrate(task)] * budget
    known = training_demos(world)
    finetune(world, policy, demos, config=TrainConfig(steps=5), replay=known)  # warm-up
    t0 = time.perf_counter()
    finetune(world, policy, demos, replay=known)
    seconds = time.perf_counter() - t0
    return {"steps": FINETUNE.steps, "batch": FINETUNE.batch_size, "finetune_s": seconds}


def experiment_run_cost(name: str) -> float:
    """Wall time of one run of `dfa experiment q2` (CF H, budget 25, seed 0) in this process,
    the counterfactual search included."""
    import torch

    from dfa_viz.experiment import runner

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the experiment's workers run
    try:
        runner.prepare.cache_clear()
        runner.offered.cache_clear()
        t0 = time.perf_counter()
        runner.run_one(runner.RunSpec(name, "object", "cf_h", 25, 0))
        return time.perf_counter() - t0
    finally:
        torch.set_num_threads(threads)


def cost_rows(name: str, run_s: float, rrd: Path, *, repeats: int = 3) -> list[Row]:
    """The rows of one world: render throughput, finetuning, recording size, experiment run."""
    r = render_throughput(name, repeats=repeats)
    f = finetune_cost(name)
    run = experiment_run_cost(name)
    size = rrd.stat().st_size if rrd.is_file() else 0
    return [
        (
            f"{name}: render throughput, one batch of {r['n']} scenes vs one scene at a time "
            f"({r['batched_fps']:.0f} vs {r['single_fps']:.0f} frames/s)",
            f"{r['ratio']:.1f}x",
            "",
            None,
        ),
        (
            f"{name}: finetune, {f['steps']} steps of {f['batch']} samples, half replayed",
            f"{f['finetune_s']:.2f} s",
            "",
            None,
        ),
        (
            f"{name}: recording of one `dfa run` ({run_s:.1f} s)",
            f"{size / 2**20:.2f} MiB",
            "",
            None,
        ),
        (f"{name}: one `dfa experiment q2` run (CF H, budget 25)", f"{run:.1f} s", "", None),
    ]
