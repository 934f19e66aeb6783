"""The page's jobs, composed from the loop's parts (policy, search, recording); no viser here.

Each function mirrors one step of dfa_viz.loop.run_loop so that the page and `dfa run` give
the same numbers for the same world, shift and seed.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dfa_viz.recording import Recorder
from policy import (
    Policy,
    augment,
    base_policy,
    evaluate,
    failing_test_task,
    finetune,
    save_policy,
)
from policy.evaluate import N_EVAL
from policy.train import FINETUNE, TrainConfig
from search import Candidate, SearchConfig, SearchResult, counterfactual_search
from sim import get_world
from sim.core import (
    Edit,
    Feedback,
    Label,
    Task,
    Trajectory,
    UserError,
    World,
    check_seed,
    check_shift,
)

MAX_TIES = 12  # counterfactual rollouts prepared for selection (the search may return more)


class Policies:
    """Base policies by world, loaded (or trained and cached) once per process."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._by_world: dict[str, Policy] = {}

    def get(self, world: World) -> Policy:
        with self._lock:
            if world.name not in self._by_world:
                self._by_world[world.name] = base_policy(world)
            return self._by_world[world.name]


def pick_task(world_name: str, shift: str, seed: int, policies: Policies):
    """The `dfa run` task for (world, shift, seed): the first failing one in its stream."""
    world = get_world(world_name)
    check_shift(shift)
    check_seed(seed)
    policy = policies.get(world)
    task, rollout = failing_test_task(world, policy, shift, seed)
    return world, task, rollout


def task_again(world_name: str, shift: str, task_seed: int, policies: Policies):
    """Rebuild a task recorded in a session (deterministic) and roll the base policy out on it."""
    world = get_world(world_name)
    check_shift(shift)
    task = world.test_task(shift, task_seed)
    return world, task, world.rollout(task, policies.get(world))


def search(
    world: World,
    policy: Policy,
    task: Task,
    demo: Trajectory,
    *,
    on_progress: Callable[[int, int, int], None] | None = None,
) -> SearchResult:
    return counterfactual_search(
        world,
        policy,
        task.scene,
        demo,
        config=SearchConfig.for_world(world),
        on_progress=on_progress,
    )


def counterfactual_rollouts(
    world: World, policy: Policy, task: Task, result: SearchResult
) -> list[Trajectory]:
    """The policy's rollout from each minimal edit's scene (the first MAX_TIES), in one batch."""
    cands = result.counterfactuals[:MAX_TIES]
    if not cands:
        return []
    scenes = [world.apply(task.scene, c.edit) for c in cands]
    return world.rollout_batch([task] * len(cands), policy, scenes=scenes)


# -- search results to and from JSON (the session log) ----------------------------------------
def search_to_json(result: SearchResult) -> dict[str, Any]:
    return {
        "size": result.size,
        "max_size": result.max_size,
        "counterfactuals": [c.to_dict() for c in result.counterfactuals],
        "tried": [c.to_dict() for c in result.tried],
    }


def _candidate(d: dict[str, Any]) -> Candidate:
    try:
        distances = np.array(
            [np.nan if v is None else float(v) for v in d["distances"]], np.float32
        )  # (T,)
        dropped = d["dropped_at"]
        matches = ~np.isnan(distances)
        if dropped is not None:
            matches[int(dropped) :] = False
        return Candidate(Edit.from_list(d["edit"]), distances, matches, dropped)
    except (KeyError, TypeError, ValueError) as e:
        raise UserError(f"malformed candidate ({type(e).__name__}: {e})") from None


def search_from_json(d: dict[str, Any]) -> SearchResult:
    return SearchResult(
        tuple(_candidate(c) for c in d["counterfactuals"]),
        tuple(_candidate(c) for c in d["tried"]),
        d["size"],
        d["max_size"],
    )


# -- adaptation -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Adaptation:
    """What "Augment & finetune" produced."""

    feedback: Feedback
    n_augmented: int
    losses: tuple[float, ...]
    success_before: float
    success_after: float
    rollout: Trajectory  # the finetuned policy on the test task
    policy: Policy | None = None  # None when read back from a session


def adapt(
    world: World,
    policy: Policy,
    task: Task,
    demo: Trajectory,
    feedback: Feedback,
    *,
    seed: int,
    steps: int = FINETUNE.steps,
    n_eval: int = N_EVAL,
    on_loss: Callable[[int, float], None] | None = None,
    on_phase: Callable[[str], None] | None = None,
) -> Adaptation:
    """Augment over the TI labels, finetune a copy, evaluate both on fresh tasks from R'."""
    if on_phase:
        on_phase("augmenting the demonstration")
    augmented = augment(world, task, demo, feedback, seed=seed)
    if on_phase:
        on_phase(f"finetuning on 1 demonstration + {len(augmented)} augmented")
    config = TrainConfig(steps, FINETUNE.batch_size, FINETUNE.lr, seed)
    tuned, losses = finetune(world, policy, [demo, *augmented], config=config, on_loss=on_loss)
    if on_phase:
        on_phase(f"evaluating on {n_eval} fresh tasks from R'")
    before = evaluate(world, policy, task, n=n_eval, seed=seed)
    after = evaluate(world, tuned, task, n=n_eval, seed=seed)
    rollout = world.rollout(task, tuned)
    return Adaptation(feedback, len(augmented), tuple(losses), before, after, rollout, tuned)


def save_adaptation(session, adaptation: Adaptation, task: Task) -> dict[str, Any]:
    """Write the finetuned rollout and checkpoint next to the session log; returns the fields
    of the "finetune" event that names them."""
    rollout_file = session.save_trajectory(adaptation.rollout, "finetuned")
    policy_dir = session.next_name("policy")
    save_policy(adaptation.policy, session.folder / policy_dir, meta={"task_seed": task.seed})
    return {
        "feedback": adaptation.feedback.to_list(),
        "n_augmented": adaptation.n_augmented,
        "losses": [round(v, 6) for v in adaptation.losses],
        "success_before": adaptation.success_before,
        "success_after": adaptation.success_after,
        "rollout_file": rollout_file,
        "policy_dir": policy_dir,
    }


def feedback_for(edit: Edit | None, marks: dict[tuple[str, str], Label]) -> Feedback:
    """The labels for an edit's concepts in edit order (concepts left unmarked are skipped)."""
    if edit is None:
        return Feedback()
    return Feedback(
        tuple(marks[(c.slot, c.concept)] for c in edit.ordered if (c.slot, c.concept) in marks)
    )


# -- recording ----------------------------------------------------------------------------------
def write_recording(
    path: Path,
    world: World,
    task: Task,
    *,
    rollout: Trajectory,
    demo: Trajectory | None,
    result: SearchResult | None,
    tie: int,
    counterfactual: Trajectory | None,
    adaptation: Adaptation | None,
    seed: int,
) -> Path:
    """Write the task's whole story to one .rrd through the loop's Recorder (observer calls in
    the loop's order)."""
    with Recorder(path, world, task) as rec:  # replaces the file only once it is whole
        rec.on_rollout("failed", rollout)
        if demo is not None:
            rec.on_rollout("demonstration", demo)
        if result is not None:
            for i, cand in enumerate(result.tried):
                rec.on_candidate(i, cand)
            chosen = _with_first(result, tie)
            rec.on_search(chosen, counterfactual)
        if adaptation is not None and demo is not None:
            rec.on_feedback(adaptation.feedback)
            rec.on_augmented(augment(world, task, demo, adaptation.feedback, seed=seed))
            for step, loss in enumerate(adaptation.losses):
                rec.on_loss(step, loss)
            rec.on_evaluation(adaptation.success_before, adaptation.success_after)
            rec.on_rollout("finetuned", adaptation.rollout)
    return path


def _with_first(result: SearchResult, tie: int) -> SearchResult:
    """The result with the selected tie ranked first (what the user looked at)."""
    cands: Sequence[Candidate] = result.counterfactuals
    if not cands or tie <= 0 or tie >= len(cands):
        return result
    order = (cands[tie], *cands[:tie], *cands[tie + 1 :])
    return dataclasses.replace(result, counterfactuals=order)
