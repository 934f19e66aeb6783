"""The four conditions of the paper's finetuning comparison and who picks which concept.

A condition names a *user concept* (sim.core.UserConcept): what a person names when they say
"this does not matter", one concept of one kind of object ("lava.presence" covers every lava
tile, so "the lava does not matter" is one answer, as it is for a person).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from policy.variants import stable_int
from sim import PAPER_WORLDS
from sim.core import Task, UserConcept, World
from sim.core.visible import visible_concepts as scene_concepts

CONDITIONS = ("nh_random", "baseline_h", "cf_h", "oracle")
CONDITION_NAMES = {
    "nh_random": "NH-random",
    "baseline_h": "Baseline H",
    "cf_h": "CF H",
    "oracle": "Oracle",
}
SIMULATED = ("baseline_h", "cf_h")
BASELINE_H = ("paper", "fixed")
"""How Baseline H's simulated user answers: "paper" (the paper's reading: each augmented
trajectory augments the right concept at the rate of right answers, else a random wrong one) or
"fixed" (one answer per seed: the right concept at that rate, else one wrong concept for every
trajectory)."""
"""The conditions whose human is a simulated user (conditions.choose), never a person."""


def condition_label(condition: str) -> str:
    """A condition's name as tables and plots print it: the simulated users say so."""
    name = CONDITION_NAMES[condition]
    return f"{name} (simulated user)" if condition in SIMULATED else name


SHIFT_KINDS = ("object", "distractor")
PAPER_BUDGETS = (5, 10, 25, 50, 75, 100)

# How often the paper's users named the right concept (design section 9), as probabilities:
# (world, shift kind) -> (without counterfactuals: Baseline H, with counterfactuals: CF H).
ACCURACY: dict[tuple[str, str], tuple[float, float]] = {
    ("nav2d", "object"): (0.28, 0.97),
    ("doorkey", "object"): (0.12, 0.93),
    ("tabletop", "object"): (0.03, 0.94),
    ("nav2d", "distractor"): (0.14, 0.94),
    ("doorkey", "distractor"): (0.32, 0.88),
    ("tabletop", "distractor"): (0.09, 0.93),
}

assert tuple(dict.fromkeys(w for w, _ in ACCURACY)) == PAPER_WORLDS, "the paper measured these"

# The paper's finetuning success at PAPER_BUDGETS trajectories (design section 9).
PAPER: dict[tuple[str, str, str], tuple[float, ...]] = {
    ("nav2d", "object", "nh_random"): (0.2, 0.3, 0.9, 1, 1, 1),
    ("nav2d", "object", "baseline_h"): (0.1, 0.1, 0.4, 0.8, 1, 1),
    ("nav2d", "object", "cf_h"): (0.7, 0.9, 1, 1, 1, 1),
    ("nav2d", "object", "oracle"): (0.8, 0.9, 1, 1, 1, 1),
    ("doorkey", "object", "nh_random"): (0, 0, 0.2, 0.3, 0.6, 0.7),
    ("doorkey", "object", "baseline_h"): (0, 0, 0, 0.2, 0.2, 0.3),
    ("doorkey", "object", "cf_h"): (0.1, 0.1, 0.4, 0.7, 0.9, 1),
    ("doorkey", "object", "oracle"): (0.1, 0.2, 0.5, 0.9, 1, 1),
    ("tabletop", "object", "nh_random"): (0, 0, 0.1, 0.1, 0.2, 0.2),
    ("tabletop", "object", "baseline_h"): (0, 0, 0, 0.1, 0.1, 0.1),
    ("tabletop", "object", "cf_h"): (0, 0, 0.4, 0.6, 0.7, 0.8),
    ("tabletop", "object", "oracle"): (0, 0.1, 0.5, 0.8, 0.9, 1),
    ("nav2d", "distractor", "nh_random"): (0, 0.1, 0.3, 0.7, 1, 1),
    ("nav2d", "distractor", "baseline_h"): (0.2, 0.4, 0.7, 1, 1, 1),
    ("nav2d", "distractor", "cf_h"): (0.9, 1, 1, 1, 1, 1),
    ("nav2d", "distractor", "oracle"): (0.9, 1, 1, 1, 1, 1),
    ("doorkey", "distractor", "nh_random"): (0, 0, 0.1, 0.3, 0.6, 0.8),
    ("doorkey", "distractor", "baseline_h"): (0, 0, 0.1, 0.4, 0.6, 0.7),
    ("doorkey", "distractor", "cf_h"): (0.1, 0.2, 0.6, 0.7, 1, 1),
    ("doorkey", "distractor", "oracle"): (0.2, 0.4, 0.5, 0.9, 1, 1),
    ("tabletop", "distractor", "nh_random"): (0, 0, 0, 0, 0.1, 0.1),
    ("tabletop", "distractor", "baseline_h"): (0, 0, 0, 0.1, 0.1, 0.1),
    ("tabletop", "distractor", "cf_h"): (0, 0.2, 0.5, 0.8, 0.9, 1),
    ("tabletop", "distractor", "oracle"): (0, 0.3, 0.7, 0.9, 1, 1),
}


def paper_value(world: str, shift: str, condition: str, budget: int) -> float | None:
    """The paper's number for this cell, or None where the paper has none."""
    if budget not in PAPER_BUDGETS:
        return None
    return PAPER[(world, shift, condition)][PAPER_BUDGETS.index(budget)]


def ti_shift(kind: str) -> str:
    """The task-irrelevant shift an experiment of this kind adapts to: object -> object_ti."""
    assert kind in SHIFT_KINDS, f"shift kind is one of {SHIFT_KINDS}, not {kind!r}"
    return f"{kind}_ti"


def visible_concepts(world: World, task: Task) -> tuple[UserConcept, ...]:
    """The concepts a person can point at in the test scene: the looks of objects that are
    there, and the presence of any optional object (adding one is always visible). The looks
    of an object that is not in the scene are not something anyone would name."""
    return scene_concepts(world.space, task.scene)


def concept_named(concepts: tuple[UserConcept, ...], name: str) -> UserConcept:
    for uc in concepts:
        if uc.name == name:
            return uc
    raise KeyError(f"no concept {name!r} among {[c.name for c in concepts]}")


def right_concept(world: World, task: Task) -> str:
    """The name of the user concept the shift generator changed (the task's planted cause)."""
    assert task.cause is not None, f"{task.shift} task has no planted cause"
    return world.space.user_concept(*task.cause).name


def user_rng(world: str, shift: str, seed: int) -> np.random.Generator:
    """The simulated users' randomness for one task. Shared by Baseline H and CF H (common
    random numbers): the same draw decides whether either user is right, so CF H is right
    whenever Baseline H is and its search offered the right concept."""
    return np.random.default_rng([seed, stable_int("user", world, shift)])


@dataclass(frozen=True)
class Choice:
    """Which concept a condition augments, and why."""

    concept: str | None
    """The user's concept; None for NH-random (a random concept per augmented trajectory)."""
    correct: bool
    """True when it is the right concept."""
    rate: float | None = None
    """Baseline H as the paper reads it: each augmented trajectory augments `concept` (the
    right one) with this probability, else a wrong visible concept drawn at random (`correct`
    is then False: no single answer is right)."""


def choose(
    condition: str,
    *,
    world: str,
    shift: str,
    seed: int,
    right: str,
    visible: tuple[str, ...],
    offered: tuple[str, ...] | None = None,
    baseline_h: str = "paper",
) -> Choice:
    """The concept a condition augments (independent of the budget).

    nh_random: no user; each augmented trajectory edits a concept drawn at random.
    oracle: always the right concept.
    baseline_h: as the paper says, "the correct concept at the same rate of correct responses
        ..., and randomly otherwise": per augmented trajectory, the right concept with the
        paper's accuracy without counterfactuals, else a random one of the other visible
        concepts (a Choice with `rate`; runner.mixed_variants draws them). With
        baseline_h="fixed", one answer per seed instead: the right concept at that rate, else
        one random other visible concept for every trajectory.
    cf_h: only when the counterfactual search offered the right concept (`offered`: the
        concepts of its best edit, empty when it found none) can the user name it, and then
        with the paper's accuracy with counterfactuals; else a random other visible concept.
    """
    if condition == "nh_random":
        return Choice(None, False)
    if condition == "oracle":
        return Choice(right, True)
    rng = user_rng(world, shift, seed)
    u = rng.random()
    wrong = [c for c in visible if c != right]
    fallback = wrong[int(rng.integers(len(wrong)))] if wrong else right
    without, with_cf = ACCURACY[(world, shift)]
    if condition == "baseline_h" and baseline_h == "paper":
        return Choice(right, False, without) if wrong else Choice(right, True)
    if condition == "baseline_h":
        assert baseline_h == "fixed", f"Baseline H is one of {BASELINE_H}, not {baseline_h!r}"
        ok = u < without
    elif condition == "cf_h":
        assert offered is not None, "CF H needs the concepts the search offered"
        ok = right in offered and u < with_cf
    else:
        raise ValueError(f"unknown condition {condition!r}; accepted: {', '.join(CONDITIONS)}")
    return Choice(right, True) if ok else Choice(fallback, fallback == right)
