"""`dfa experiment q2`: the paper's finetuning comparison, as a tyro-friendly function."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Literal

import tyro

World = Literal["nav2d", "doorkey", "tabletop"]
Condition = Literal["nh_random", "baseline_h", "cf_h", "oracle"]


def experiment_q2(
    worlds: Annotated[tuple[World, ...], tyro.conf.arg(aliases=("--world",))] = (
        "nav2d",
        "doorkey",
        "tabletop",
    ),
    shift: Literal["object", "distractor", "both"] = "both",
    budgets: tuple[int, ...] = (5, 10, 25, 50, 75, 100),
    seeds: int = 5,
    workers: int = 2,
    backend: Literal["local", "ray"] = "local",
    out: Path = Path("recordings/experiments/q2"),
    conditions: tuple[Condition, ...] = ("nh_random", "baseline_h", "cf_h", "oracle"),
    steps: int = 300,
    steps_per_trajectory: int = 10,
    replay_share: float = 0.5,
    layouts: Literal["train", "task"] = "train",
    sources: Literal["all", "user"] = "all",
    n_eval: int = 10,
    max_size: int = 2,
    ray_address: str | None = None,
    progress: bool = True,
) -> None:
    """Reproduce the paper's finetuning comparison: success against finetuning trajectories.

    For every world, shift, condition, budget and seed, one run takes the first task-irrelevant
    test task of that seed the base policy fails, the expert's demonstration of it, and a
    concept to augment: NH-random a random concept for each augmented trajectory; Baseline H a
    simulated user who names the right concept at the paper's rate without counterfactuals;
    CF H one who sees the real counterfactual search's answer and names the right concept at
    the paper's rate with counterfactuals (never when the search found nothing or the wrong
    thing); Oracle always the right one. The budget is the number of finetuning trajectories:
    the demonstration plus budget - 1 distinct variants of it over the concept (same actions,
    edited states), repeated from the demonstration on when the concept has fewer variants.
    A copy of the base policy is finetuned and scored on fresh tasks from the user's reward.

    Writes OUT/runs.csv (every run), OUT/table.md (means with 95% confidence intervals beside
    the paper's numbers), OUT/plots/<world>-<shift>.png and OUT/curves.rrd. Runs already in
    OUT/runs.csv are skipped, so an interrupted experiment resumes where it stopped. The same
    seeds give the same runs.csv whichever backend ran them.

    Args:
        worlds: which worlds.
        shift: object, distractor, or both.
        budgets: finetuning trajectories per run (the demonstration counts as one).
        seeds: seeds 0 .. SEEDS-1 (each picks a test task and every random choice of its runs).
        workers: runs executed side by side (processes locally, CPUs of a local Ray instance).
        backend: local (a process pool on this machine) or ray (pip install 'dfa[ray]').
        out: the results folder.
        conditions: which conditions.
        steps: fewest finetuning gradient steps per run.
        steps_per_trajectory: a run finetunes max(STEPS, this x budget) steps.
        replay_share: share of every finetuning batch replayed from the base policy's
            training demonstrations (0: none).
        layouts: where the fresh evaluation tasks put the objects: in a random training
            layout, or where the test task has them.
        sources: what variants are made from: the training demonstrations and the user's,
            or the user's demonstration only.
        n_eval: fresh tasks each finetuned policy is scored on.
        max_size: largest edit the counterfactual search tries (CF H).
        ray_address: an existing Ray cluster ("auto", "ray://host:10001"); default: start one here.
        progress: show a progress bar.
    """
    from dfa_viz.experiment.experiment import Plan, run_experiment
    from dfa_viz.experiment.runner import Settings
    from sim.core import UserError

    if seeds < 1:
        raise UserError(f"--seeds is how many seeds to run, at least 1, not {seeds}")
    for name, value in (
        ("steps", steps),
        ("steps-per-trajectory", steps_per_trajectory),
        ("n-eval", n_eval),
        ("max-size", max_size),
    ):
        if value < 1:
            raise UserError(f"--{name} must be at least 1, not {value}")
    if not 0.0 <= replay_share < 1.0:
        raise UserError(f"--replay-share is a share of a batch in [0, 1), not {replay_share}")
    plan = Plan(
        worlds=tuple(dict.fromkeys(worlds)),
        shifts=("object", "distractor") if shift == "both" else (shift,),
        conditions=tuple(dict.fromkeys(conditions)),
        budgets=tuple(sorted(set(budgets))),
        seeds=tuple(range(seeds)),
    )
    summary = run_experiment(
        plan,
        out=out,
        settings=Settings(
            n_eval=n_eval,
            steps=steps,
            steps_per_trajectory=steps_per_trajectory,
            max_size=max_size,
            replay_share=replay_share,
            layouts=layouts,
            sources=sources,
        ),
        backend=backend,
        workers=workers,
        ray_address=ray_address,
        progress=progress,
    )
    print(
        f"{summary.planned} runs planned: {summary.skipped} already in {summary.out}, "
        f"{summary.executed} run now in {summary.wall_s:.0f} s"
    )
    for path in summary.reports:
        print(f"  {path}")


EXPERIMENTS = {"q2": experiment_q2}


def experiment_main(args: Sequence[str]) -> None:
    """`dfa experiment <name> ...`: dispatch to one experiment (args after "experiment")."""
    tyro.extras.subcommand_cli_from_dict(EXPERIMENTS, args=list(args), prog="dfa experiment")
