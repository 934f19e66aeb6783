"""One run of the finetuning comparison: world, shift, condition, budget, seed -> success.

A run is a pure function of its spec and the experiment's settings (and the cached base
policy): the same spec gives the same row on any worker, process or machine. Randomness comes
only from seeded generators keyed by the spec's names, never from the order runs execute in.

What one run does:
1. The task: the first `<shift>_ti` test task of the seed's stream that the base policy fails
   (policy.failing_test_task), and the scripted expert's demonstration of it.
2. The concept (conditions.choose): random per trajectory (NH-random), the right one
   (Oracle), or a simulated user's pick (Baseline H; CF H after the real counterfactual search
   on this task with the base policy).
3. The finetuning set: the demonstration plus budget - 1 distinct variants over the concept,
   taken in turn from the base policy's 10 training demonstrations and the user's
   demonstration (augmentation.sources), cycled to exactly `budget` trajectories when the
   concept has fewer variants.
4. Finetune a copy of the base policy (seeded by the run's seed) on that set for
   max(steps, steps_per_trajectory * budget) steps, with its own
   training demonstrations replayed as `replay_share` of every batch, and evaluate it on
   `n_eval` fresh tasks from R' placed in the training layouts (the same tasks for every
   condition and budget of the seed).
"""

from __future__ import annotations

import functools
import os
import socket
import time
from dataclasses import asdict, dataclass

from dfa_viz.experiment import augmentation as aug
from dfa_viz.experiment.conditions import (
    CONDITIONS,
    SHIFT_KINDS,
    UserConcept,
    choose,
    concept_named,
    concept_of_change,
    right_concept,
    ti_shift,
    visible_concepts,
)
from policy.evaluate import N_EVAL
from policy.train import FINETUNE
from sim.core import Task, Trajectory

# the columns of runs.csv, in order; the first five are a run's key
COLUMNS = (
    "world",
    "shift",
    "condition",
    "budget",
    "seed",
    "success",
    "success_before",
    "task_seed",
    "right_concept",
    "chosen_concept",
    "correct",
    "cf_edit",
    "n_distinct",
    "final_loss",
)
KEY = COLUMNS[:5]


@dataclass(frozen=True)
class Settings:
    """What every run of one experiment shares; a results folder keeps to one set of these."""

    n_eval: int = N_EVAL
    """Fresh tasks from R' each finetuned policy is evaluated on (the paper's 10)."""
    steps: int = FINETUNE.steps
    """Fewest finetuning gradient steps (batch FINETUNE.batch_size, learning rate FINETUNE.lr)."""
    steps_per_trajectory: int = 10
    """Steps per finetuning trajectory above that: a run takes max(steps, this * budget), so
    a large budget gets as many passes over its data as a small one."""
    max_size: int = 2
    """Largest edit the counterfactual search tries (CF H)."""
    replay_share: float = 0.5
    """Share of every finetuning batch replayed from the base policy's training demonstrations."""
    layouts: str = "train"
    """Where the fresh evaluation tasks put the objects (World.fresh_tasks)."""
    sources: str = "all"
    """What variants are made from: "all" (the training demonstrations and the user's) or
    "user" (the user's demonstration only, as in the paper)."""

    def to_dict(self) -> dict:
        return asdict(self)

    def steps_for(self, budget: int) -> int:
        return max(self.steps, self.steps_per_trajectory * budget)


@dataclass(frozen=True, order=True)
class RunSpec:
    """One run: which world, shift kind, condition, budget and seed."""

    world: str
    shift: str
    """object or distractor (the task-irrelevant shift of that kind)."""
    condition: str
    budget: int
    """Finetuning trajectories: the demonstration plus budget - 1 variants (cycled if short)."""
    seed: int

    def __post_init__(self) -> None:
        assert self.shift in SHIFT_KINDS, f"shift is one of {SHIFT_KINDS}, not {self.shift!r}"
        assert self.condition in CONDITIONS, f"condition is one of {CONDITIONS}"
        assert self.budget >= 1, f"budget counts trajectories, at least 1, not {self.budget}"

    @property
    def key(self) -> tuple[str, str, str, int, int]:
        return (self.world, self.shift, self.condition, self.budget, self.seed)


@dataclass(frozen=True)
class Prepared:
    """What every run on one (world, shift, seed) shares."""

    task: Task
    demo: Trajectory
    known: tuple[Trajectory, ...]
    """The base policy's training demonstrations (sources of variants, and replayed)."""
    success_before: float
    """The base policy's success on the same fresh tasks the finetuned ones are scored on."""
    visible: tuple[UserConcept, ...]
    right: str


# Bounded per-process caches: a worker that runs several conditions or budgets of the same
# task prepares it (and searches it) once. Ordered submission keeps those runs together.
@functools.lru_cache(maxsize=3)
def _policy(world_name: str):
    from policy import base_policy
    from sim import get_world

    return base_policy(get_world(world_name))


@functools.lru_cache(maxsize=3)
def _known(world_name: str) -> tuple[Trajectory, ...]:
    from policy import training_demos
    from sim import get_world

    return tuple(training_demos(get_world(world_name)))


@functools.lru_cache(maxsize=8)
def prepare(
    world_name: str, shift: str, seed: int, n_eval: int, layouts: str = "train"
) -> Prepared:
    from policy import evaluate, failing_test_task
    from sim import get_world

    world, policy = get_world(world_name), _policy(world_name)
    task, _ = failing_test_task(world, policy, ti_shift(shift), seed)
    demo = world.demonstrate(task)
    before = evaluate(world, policy, task, n=n_eval, seed=seed, layouts=layouts)
    return Prepared(
        task,
        demo,
        _known(world_name),
        before,
        visible_concepts(world, task),
        right_concept(world, task),
    )


@functools.lru_cache(maxsize=8)
def offered(world_name: str, shift: str, seed: int, n_eval: int, layouts: str, max_size: int):
    """The counterfactual search on the task: (concepts of its best edit, the edit as text)."""
    from search import SearchConfig, counterfactual_search
    from sim import get_world

    world, prep = get_world(world_name), prepare(world_name, shift, seed, n_eval, layouts)
    result = counterfactual_search(
        world,
        _policy(world_name),
        prep.task.scene,
        prep.demo,
        config=SearchConfig.for_world(world, max_size=max_size),
    )
    if result.best is None:
        return (), "none"
    edit = result.best.edit
    names = tuple(dict.fromkeys(concept_of_change(c.slot, c.concept) for c in edit.ordered))
    return names, str(edit)


def run_one(spec: RunSpec, settings: Settings = Settings()) -> dict[str, object]:
    """Run one spec; returns its runs.csv row (values as strings) plus its wall time
    `duration_s`, the CPU time of this process `cpu_s` (what the run costs on an idle core)
    and `host` (host:pid of the worker)."""
    from policy import evaluate, finetune
    from policy.train import TrainConfig
    from sim import get_world

    t0, cpu0 = time.perf_counter(), time.process_time()
    world = get_world(spec.world)
    prep = prepare(spec.world, spec.shift, spec.seed, settings.n_eval, settings.layouts)
    cf_concepts, cf_edit = None, ""
    if spec.condition == "cf_h":
        cf_concepts, cf_edit = offered(
            spec.world,
            spec.shift,
            spec.seed,
            settings.n_eval,
            settings.layouts,
            settings.max_size,
        )
    names = tuple(c.name for c in prep.visible)
    choice = choose(
        spec.condition,
        world=spec.world,
        shift=spec.shift,
        seed=spec.seed,
        right=prep.right,
        visible=names,
        offered=cf_concepts,
    )
    n = spec.budget - 1
    srcs = (
        aug.sources(prep.task, prep.demo, prep.known)
        if settings.sources == "all"
        else [aug.Source(prep.task, prep.demo)]
    )
    if choice.concept is None:
        ops = aug.random_concept_variants(world, srcs, prep.visible, n, seed=spec.seed)
    else:
        concept = concept_named(prep.visible, choice.concept)
        ops = aug.variants_for_concept(world, srcs, concept, n, informed=True, seed=spec.seed)
    variants = aug.render_from_sources(world, srcs, ops)
    demos = aug.fill_budget(prep.demo, variants, spec.budget)
    steps = settings.steps_for(spec.budget)
    config = TrainConfig(steps, FINETUNE.batch_size, FINETUNE.lr, spec.seed)
    tuned, losses = finetune(
        world,
        _policy(spec.world),
        demos,
        config=config,
        replay=prep.known,
        replay_share=settings.replay_share,
    )
    success = evaluate(
        world, tuned, prep.task, n=settings.n_eval, seed=spec.seed, layouts=settings.layouts
    )
    row: dict[str, object] = {
        "world": spec.world,
        "shift": spec.shift,
        "condition": spec.condition,
        "budget": spec.budget,
        "seed": spec.seed,
        "success": f"{success:.4g}",
        "success_before": f"{prep.success_before:.4g}",
        "task_seed": prep.task.seed,
        "right_concept": prep.right,
        "chosen_concept": choice.concept or "random",
        "correct": int(choice.correct),
        "cf_edit": cf_edit,
        "n_distinct": 1 + len(variants),
        "final_loss": f"{losses[-1]:.6g}",
    }
    assert tuple(row) == COLUMNS, "row and COLUMNS disagree"
    row = {k: str(v) for k, v in row.items()}
    return {
        **row,
        "duration_s": round(time.perf_counter() - t0, 3),
        "cpu_s": round(time.process_time() - cpu0, 3),
        "host": f"{socket.gethostname()}:{os.getpid()}",
    }


def init_worker() -> None:
    """Every run executes with one torch thread (results must not depend on the thread count,
    and parallelism comes from running runs side by side)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import torch

    torch.set_num_threads(1)


def run_in_worker(spec: RunSpec, settings: Settings) -> dict[str, object]:
    """The function a backend ships to a worker: one thread, then the run."""
    init_worker()
    return run_one(spec, settings)
