"""One run of the finetuning comparison: world, shift, condition, budget, seed -> success.

A run is a pure function of its spec and the experiment's settings (and the committed base
policy): the same spec gives the same row on any worker, process or machine. Randomness comes
only from seeded generators keyed by the spec's names, never from the order runs execute in.

A run is the loop's own steps (dfa_viz.loop) with a simulated user in the paper's place:
1. The task: the first `<shift>_ti` test task of the seed's stream that the base policy fails
   (policy.failing_test_task), and the scripted expert's demonstration of it.
2. The concept (conditions.choose): random per trajectory (NH-random), the right one (Oracle),
   per trajectory the right one at the paper's rate and a random wrong one otherwise (Baseline
   H as the paper reads it; Settings.baseline_h "fixed": one pick per seed), or a simulated
   user's pick after the loop's diagnosis on this task (CF H).
3. The feedback: that concept marked task-irrelevant, with what a person who knows R' accepts
   (policy.variants.acceptable_if_irrelevant), exactly as the simulated user of `dfa run`
   marks it; NH-random instead augments a random concept, any value, per trajectory.
4. loop.adapt with the settings' AdaptConfig at this budget (the same call `dfa run` and the
   page make), then policy.evaluate.score on the same fresh tasks for every condition and
   budget of the seed: carrying the shift (`success`) and from all of R' (`success_all`), on
   layouts and values no finetuning trajectory shows (policy.heldout); beside them how many
   distinct scenes they are (`eval_distinct`, `eval_distinct_all`), how many start from a
   finetuning trajectory's scene or layout (`eval_overlap`, `eval_layout_overlap`: 0) and how
   many values of the cause are held out (`eval_held_values`: 0 where too few to hold out).
"""

from __future__ import annotations

import functools
import os
import socket
import time
from dataclasses import asdict, dataclass, field

from dfa_viz.configs import AdaptConfig, Finetuning
from dfa_viz.experiment.conditions import (
    CONDITIONS,
    SHIFT_KINDS,
    Choice,
    choose,
    concept_named,
    right_concept,
    ti_shift,
    visible_concepts,
)
from policy.evaluate import Score
from sim.core import Feedback, Label, Task, Trajectory, UserConcept, World

# the columns of runs.csv, in order; the first five are a run's key
COLUMNS = (
    "world",
    "shift",
    "condition",
    "budget",
    "seed",
    "success",
    "success_before",
    "success_all",
    "success_all_before",
    "task_seed",
    "right_concept",
    "chosen_concept",
    "correct",
    "cf_edit",
    "n_distinct",
    "final_loss",
    "eval_distinct",
    "eval_distinct_all",
    "eval_overlap",
    "eval_layout_overlap",
    "eval_held_values",
)
KEY = COLUMNS[:5]


@dataclass(frozen=True)
class Settings:
    """What every run of one experiment shares; a results folder keeps to one set of these."""

    finetuning: Finetuning = field(default_factory=Finetuning)
    """How each run finetunes and scores (its budget is the run's own)."""
    max_size: int = 2
    """Largest edit the counterfactual search tries (CF H)."""
    baseline_h: str = "paper"
    """How Baseline H's simulated user answers (conditions.BASELINE_H): "paper", per augmented
    trajectory, or "fixed", one answer per seed."""

    def to_dict(self) -> dict:
        """As config.json holds them: without `dagger_rounds` where it is 0 and `replay_looks`
        where it is "training", so that folders made before they were chosen read back the
        same."""
        doc = asdict(self)
        if not self.finetuning.dagger_rounds:
            del doc["finetuning"]["dagger_rounds"]
        if self.finetuning.replay_looks == "training":
            del doc["finetuning"]["replay_looks"]
        return doc

    def config(self, budget: int) -> AdaptConfig:
        return AdaptConfig(budget, self.finetuning)


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
    before: Score
    """The base policy on the same fresh tasks the finetuned ones are scored on."""
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
def prepare(world_name: str, shift: str, seed: int, n_eval: int) -> Prepared:
    from policy import failing_test_task
    from policy.evaluate import score
    from sim import get_world

    world, policy = get_world(world_name), _policy(world_name)
    task, _ = failing_test_task(world, policy, ti_shift(shift), seed)
    demo = world.demonstrate(task)
    return Prepared(
        task,
        demo,
        _known(world_name),
        score(world, policy, task, n=n_eval, seed=seed),
        visible_concepts(world, task),
        right_concept(world, task),
    )


@functools.lru_cache(maxsize=8)
def offered(world_name: str, shift: str, seed: int, n_eval: int, max_size: int):
    """The loop's diagnosis of the task: (user concepts of its best edit, the edit as text)."""
    from dfa_viz.loop import diagnose
    from search import SearchConfig
    from sim import get_world

    world, prep = get_world(world_name), prepare(world_name, shift, seed, n_eval)
    diagnosis = diagnose(
        world,
        _policy(world_name),
        prep.task,
        prep.demo,
        config=SearchConfig.for_world(world, max_size=max_size),
    )
    edit = diagnosis.edit
    if edit is None:
        return (), "none"
    space = world.space
    names = tuple(dict.fromkeys(space.user_concept(c.slot, c.concept).name for c in edit.ordered))
    return names, str(edit)


def feedback_over(world: World, task: Task, concept: UserConcept) -> Feedback:
    """The user concept marked task-irrelevant, as the simulated user of `dfa run` marks a
    concept the counterfactual changes (a label on one of its slots speaks for the kind)."""
    from policy.variants import acceptable_if_irrelevant

    slot, name = concept.members[0]
    acceptable = acceptable_if_irrelevant(world, task.reward, slot, name)
    return Feedback((Label(slot, name, False, acceptable),))


def _walk(world: World, prep: Prepared, config: AdaptConfig, seed: int, tag: str, draw, whats):
    """budget - 1 variants from the sources in turn (those on held-out layouts left out), the
    i-th over the i-th of `draw(rng, whats)`'s picks (`whats`: the concepts, each restricted to
    what the evaluation does not hold out), seeded by (seed, tag)."""
    import numpy as np

    from policy import variants as A
    from policy.heldout import plan

    holdout = plan(world, prep.task, seed)
    known = holdout.sources(world, prep.known) if config.finetuning.sources == "all" else ()
    srcs = A.sources(prep.task, prep.demo, known)
    whats = [holdout.restrict(w) for w in whats]
    rng = np.random.default_rng([seed, A.stable_int(tag, world.name, prep.task.shift)])
    picks: list[A.Irrelevant] = []

    def pick(i: int) -> A.Irrelevant:
        while len(picks) <= i:
            picks.append(draw(rng, whats))
        return picks[i]

    chosen = A.variants(
        world, srcs, pick, config.budget - 1, seed=seed, like=prep.task.scene, n_concepts=len(whats)
    )
    return A.render(world, srcs, chosen)


def nh_random_variants(world: World, prep: Prepared, config: AdaptConfig, seed: int):
    """NH-random: budget - 1 variants, the i-th over a concept drawn uniformly from the
    visible ones (any instantiation), from the sources in turn."""
    from policy import variants as A

    uninformed = [A.over(world, prep.task, uc, informed=False) for uc in prep.visible]
    return _walk(
        world, prep, config, seed, "nh_random",
        lambda rng, whats: whats[int(rng.integers(len(whats)))], uninformed,
    )  # fmt: skip


def mixed_variants(world: World, prep: Prepared, config: AdaptConfig, seed: int, rate: float):
    """Baseline H as the paper reads it: budget - 1 variants, the i-th over the right concept
    with probability `rate`, else over one of the other visible concepts drawn uniformly, each
    with the values a person who calls it task-irrelevant accepts, from the sources in turn."""
    from policy import variants as A

    informed = [A.over(world, prep.task, uc) for uc in prep.visible]
    right = [i for i, uc in enumerate(prep.visible) if uc.name == prep.right]
    wrong = [i for i, uc in enumerate(prep.visible) if uc.name != prep.right]
    assert right and wrong, "a mixed Baseline H needs the right concept and a wrong one"

    def draw(rng, whats):
        if rng.random() < rate:
            return whats[right[0]]
        return whats[wrong[int(rng.integers(len(wrong)))]]

    return _walk(world, prep, config, seed, "baseline_h", draw, informed)


@dataclass(frozen=True)
class Taken:
    """What a run's condition made of its failure: the prepared task, the concept chosen, the
    feedback on it (empty for NH random and the paper's Baseline H) and, for those, the
    variants drawn instead."""

    prep: Prepared
    choice: Choice
    feedback: Feedback
    augmented: list[Trajectory] | None
    cf_edit: str


def take_feedback(world: World, spec: RunSpec, settings: Settings) -> Taken:
    """A run's steps up to adaptation, the same wherever the run is made or made again."""
    n_eval = settings.finetuning.n_eval
    prep = prepare(spec.world, spec.shift, spec.seed, n_eval)
    cf_concepts, cf_edit = None, ""
    if spec.condition == "cf_h":
        cf_concepts, cf_edit = offered(spec.world, spec.shift, spec.seed, n_eval, settings.max_size)
    choice = choose(
        spec.condition,
        world=spec.world,
        shift=spec.shift,
        seed=spec.seed,
        right=prep.right,
        visible=tuple(c.name for c in prep.visible),
        offered=cf_concepts,
        baseline_h=settings.baseline_h,
    )
    if choice.rate is not None:
        config = settings.config(spec.budget)
        variants = mixed_variants(world, prep, config, spec.seed, choice.rate)
        return Taken(prep, choice, Feedback(), variants, cf_edit)
    if choice.concept is None:
        config = settings.config(spec.budget)
        return Taken(
            prep, choice, Feedback(), nh_random_variants(world, prep, config, spec.seed), cf_edit
        )
    concept = concept_named(prep.visible, choice.concept)
    return Taken(prep, choice, feedback_over(world, prep.task, concept), None, cf_edit)


def chosen_name(choice: Choice) -> str:
    """runs.csv's chosen_concept: the concept, "random" (NH-random) or, for the paper's
    Baseline H, "<right> at <rate>, else random"."""
    if choice.rate is not None:
        return f"{choice.concept} at {choice.rate:.2f}, else random"
    return choice.concept or "random"


def run_one(spec: RunSpec, settings: Settings = Settings()) -> dict[str, object]:
    """Run one spec; returns its runs.csv row (values as strings) plus its wall time
    `duration_s`, the CPU time of this process `cpu_s` (what the run costs on an idle core)
    and `host` (host:pid of the worker)."""
    from dfa_viz.loop import adapt
    from policy.evaluate import freshness, score
    from sim import get_world

    t0, cpu0 = time.perf_counter(), time.process_time()
    world = get_world(spec.world)
    config = settings.config(spec.budget)
    n_eval = settings.finetuning.n_eval
    taken = take_feedback(world, spec, settings)
    prep, choice, feedback, augmented = taken.prep, taken.choice, taken.feedback, taken.augmented
    cf_edit = taken.cf_edit
    adaptation = adapt(
        world,
        _policy(spec.world),
        prep.task,
        prep.demo,
        feedback,
        config=config,
        seed=spec.seed,
        known=prep.known,
        augmented=augmented,
    )
    after = score(world, adaptation.policy, prep.task, n=n_eval, seed=spec.seed)
    starts = [t.scenes[0] for t in (prep.demo, *adaptation.augmented)]
    fresh = freshness(world, prep.task, starts, n=n_eval, seed=spec.seed)
    row: dict[str, object] = {
        "world": spec.world,
        "shift": spec.shift,
        "condition": spec.condition,
        "budget": spec.budget,
        "seed": spec.seed,
        "success": f"{after.on_shift:.4g}",
        "success_before": f"{prep.before.on_shift:.4g}",
        "success_all": f"{after.on_all:.4g}",
        "success_all_before": f"{prep.before.on_all:.4g}",
        "task_seed": prep.task.seed,
        "right_concept": prep.right,
        "chosen_concept": chosen_name(choice),
        "correct": int(choice.correct),
        "cf_edit": cf_edit,
        "n_distinct": 1 + len(adaptation.augmented),
        "final_loss": f"{adaptation.losses[-1]:.6g}",
        "eval_distinct": fresh.distinct,
        "eval_distinct_all": fresh.distinct_all,
        "eval_overlap": fresh.overlap,
        "eval_layout_overlap": fresh.layout_overlap,
        "eval_held_values": len(fresh.held_values),
    }
    assert tuple(row) == COLUMNS, "row and COLUMNS disagree"
    row = {k: str(v) for k, v in row.items()}
    return {
        **row,
        "duration_s": round(time.perf_counter() - t0, 3),
        "cpu_s": round(time.process_time() - cpu0, 3),
        "host": f"{socket.gethostname()}:{os.getpid()}",
    }
