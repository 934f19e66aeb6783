"""The DFA loop (the paper's Algorithm 1), written once: each step a function over values that
returns a new copy of the run's one record (dfa_viz.run_record.RunRecord).

    start         the base policy rolled out on the test task            -> RunRecord
    judged        the user says whether that rollout failed
    demonstrated  the user's demonstration (refused unless it succeeds under R')
    diagnose      the counterfactual search and the counterfactual rollouts -> Diagnosis
    (feedback)    the user marks each edited concept TI or TR              -> Feedback
    adapt         variants over the TI concepts, a finetuned copy          -> Adaptation
    evaluate      both policies on fresh tasks, on the shift and overall   -> Evaluation

(`adapt_and_evaluate`: the last two as one step; `diagnosed`, `adapted`: a result recorded.)

`dfa run` (run_loop below), the page (dfa_viz.app.state) and the finetuning experiment's
runner (dfa_viz.experiment.runner) compose these steps; none re-implements one. The recorder
writes a run's .rrd from its RunRecord, the page's session persists it as events, and
`dfa run --json` prints `RunRecord.to_json()`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

from dfa_viz.configs import AdaptConfig
from dfa_viz.run_record import Adaptation, Diagnosis, Evaluation, RunRecord
from dfa_viz.users import User
from policy import Policy, finetune, training_demos
from policy.evaluate import N_EVAL, freshness, score
from policy.replay_looks import irrelevant, replay_for
from policy.variants import fill_budget, render, sources, spread_looks, variants
from search import SearchConfig, SearchResult, counterfactual_search
from sim.core import EMPTY, Feedback, Task, Trajectory, World, require_success

MAX_TIES = 12  # counterfactual rollouts prepared for selection (the search may return more)
ProgressCallback = Callable[[int, int, int], None]  # (size, done, total) of the search
LossCallback = Callable[[int, float], None]  # (step, loss) while finetuning


# -- the steps ----------------------------------------------------------------------------------
def start(world: World, policy: Policy, task: Task, *, shift: str, seed: int) -> RunRecord:
    """The base policy rolled out on the test task."""
    return RunRecord(world.name, shift, seed, task, world.rollout(task, policy))


def judged(record: RunRecord, failed: bool) -> RunRecord:
    return dataclasses.replace(record, failed=failed)


def demonstrated(record: RunRecord, demo: Trajectory, source: str = "expert") -> RunRecord:
    """The record with the user's demonstration; one that does not succeed is refused."""
    require_success(record.task, demo, source=f"the {source} demonstration")
    return dataclasses.replace(record, demo=demo, demo_source=source)


def diagnose(
    world: World,
    policy: Policy,
    task: Task,
    demo: Trajectory,
    *,
    config: SearchConfig,
    on_progress: ProgressCallback | None = None,
) -> Diagnosis:
    """The smallest concept edits after which the policy follows the demonstration (or does
    the task, World.counterfactual), and the policy's rollouts from them (one batch)."""
    result = counterfactual_search(
        world, policy, task.scene, demo, config=config, on_progress=on_progress, task=task
    )
    return Diagnosis(result, tuple(counterfactual_rollouts(world, policy, task, result)))


def diagnosed(record: RunRecord, diagnosis: Diagnosis) -> RunRecord:
    """The record with the search's diagnosis; no concept marked yet."""
    return dataclasses.replace(record, diagnosis=diagnosis, feedback=Feedback())


def counterfactual_rollouts(
    world: World, policy: Policy, task: Task, result: SearchResult
) -> list[Trajectory]:
    """The policy's rollout from each minimal edit's scene (the first MAX_TIES), in one batch."""
    cands = result.counterfactuals[:MAX_TIES]
    if not cands:
        return []
    scenes = world.apply_batch(task.scene, [c.edit for c in cands])
    return world.rollout_batch([task] * len(cands), policy, scenes=scenes)


def augmentation(
    world: World,
    task: Task,
    demo: Trajectory,
    feedback: Feedback,
    *,
    config: AdaptConfig,
    known: Sequence[Trajectory],
    seed: int,
    held_out: bool = True,
) -> list[Trajectory]:
    """Up to budget - 1 variants over the TI labels from the config's sources, none on what the
    evaluation holds out (policy.heldout.plan; held_out=False: all); first in config's looks."""
    what, holdout = irrelevant(world, task, feedback, seed=seed, held_out=held_out)
    if what is None:
        return []
    if holdout is not None:
        known = holdout.sources(world, known)
    srcs = sources(task, demo, known if config.finetuning.sources == "all" else ())
    like = task.scene if config.finetuning.looks == "test" else spread_looks(task.scene, what)
    chosen = variants(world, srcs, lambda i: what, config.budget - 1, seed=seed, like=like)
    return render(world, srcs, chosen)


def adapt(
    world: World,
    base: Policy,
    task: Task,
    demo: Trajectory,
    feedback: Feedback,
    *,
    config: AdaptConfig,
    seed: int,
    known: Sequence[Trajectory] | None = None,
    augmented: Sequence[Trajectory] | None = None,
    on_loss: LossCallback | None = None,
) -> Adaptation:
    """Finetune a copy of `base` on exactly `config.budget` trajectories: the demonstration and
    its variants over the TI labels (or the `augmented` given), with the base policy's training
    demonstrations (`known`, made here when None and read) replayed in every batch."""
    reads = world.benchmark and config.finetuning.uses_training_demos
    known = (training_demos(world) if reads else ()) if known is None else known
    if augmented is None:
        augmented = augmentation(world, task, demo, feedback, config=config, known=known, seed=seed)
    ft = config.finetuning
    replay = replay_for(
        world, base, task, feedback, known, looks=ft.replay_looks, share=ft.replay_share, seed=seed
    )
    tuned, losses = finetune(
        world,
        base,
        fill_budget(demo, augmented, config.budget),
        config=config.train_config(seed, world.cloning.shift_px),
        replay=replay,
        replay_share=ft.replay_share,
        rounds=ft.dagger_rounds,
        task=task,
        on_loss=on_loss,
    )
    return Adaptation(
        feedback, tuple(augmented), config.budget, tuple(losses), world.rollout(task, tuned), tuned
    )


def evaluate(
    world: World,
    base: Policy,
    tuned: Policy,
    task: Task,
    *,
    n: int = N_EVAL,
    seed: int,
    finetuned_on: Sequence[Trajectory] = (),
) -> Evaluation:
    """Both policies on the same fresh tasks: carrying the shift, and from all of R'; with
    how fresh those are to the trajectories `finetuned_on` (the demonstration, the variants)."""
    starts = [t.scenes[0] for t in finetuned_on]
    return Evaluation(
        score(world, base, task, n=n, seed=seed),
        score(world, tuned, task, n=n, seed=seed),
        freshness(world, task, starts, n=n, seed=seed),
    )


def adapt_and_evaluate(
    world: World,
    base: Policy,
    record: RunRecord,
    *,
    config: AdaptConfig,
    known: Sequence[Trajectory] | None = None,
    on_loss: LossCallback | None = None,
    on_scoring: Callable[[], None] | None = None,
) -> tuple[Adaptation, Evaluation | None]:
    """Adapt on the record's demonstration and feedback, then score both policies on the
    config's number of fresh tasks (`on_scoring` called in between); a world without fresh
    tasks is not scored."""
    assert record.demo is not None, "adapting needs a demonstration"
    adaptation = adapt(
        world,
        base,
        record.task,
        record.demo,
        record.feedback,
        config=config,
        seed=record.seed,
        known=known,
        on_loss=on_loss,
    )
    if not world.benchmark:
        return adaptation, None
    if on_scoring is not None:
        on_scoring()
    n = config.finetuning.n_eval
    tuned_on = [record.demo, *adaptation.augmented]
    evaluation = evaluate(
        world, base, adaptation.policy, record.task, n=n, seed=record.seed, finetuned_on=tuned_on
    )
    return adaptation, evaluation


def adapted(record: RunRecord, adaptation: Adaptation, evaluation: Evaluation | None) -> RunRecord:
    """The record with the adaptation (and the feedback it used) and its scores."""
    return dataclasses.replace(
        record, adaptation=adaptation, evaluation=evaluation, feedback=adaptation.feedback
    )


def run_loop(
    world: World,
    policy: Policy,
    task: Task,
    user: User,
    *,
    seed: int = 0,
    search: SearchConfig | None = None,
    config: AdaptConfig = AdaptConfig(),
    known: Sequence[Trajectory] | None = None,
    on_progress: ProgressCallback | None = None,
    on_loss: LossCallback | None = None,
) -> RunRecord:
    """One pass of Algorithm 1 on `task` with `user` answering; the record of everything."""
    record = start(world, policy, task, shift=task.shift, seed=seed)
    record = judged(record, user.judge(task, record.rollout))
    if not record.failed:
        return record
    record = demonstrated(record, user.demonstrate(task), user.source)
    diagnosis = diagnose(
        world,
        policy,
        task,
        record.demo,
        config=search or SearchConfig.for_world(world),
        on_progress=on_progress,
    )
    record = diagnosed(record, diagnosis)
    feedback = user.label(task, diagnosis.edit if diagnosis.edit is not None else EMPTY)
    record = dataclasses.replace(record, feedback=feedback)
    if policy.net is None:  # an ONNX graph: diagnosed, not finetuned
        return record
    adaptation, evaluation = adapt_and_evaluate(
        world, policy, record, config=config, known=known, on_loss=on_loss
    )
    return adapted(record, adaptation, evaluation)
