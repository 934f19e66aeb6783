"""The options of the experiments, `dfa experiment q2` (Q2Args) and `dfa experiment explain`
(ExplainArgs), and the explanation benchmark's name tables. Light to import: nothing here
loads torch, MuJoCo, rerun or viser.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import tyro

from dfa_viz.configs import Finetuning
from dfa_viz.experiment.conditions import CONDITIONS, PAPER_BUDGETS, SHIFT_KINDS
from policy.methods import METHODS
from sim import PAPER_WORLDS
from sim.core import SHIFTS

EXPLAINERS = ("counterfactual", *METHODS, "random")
"""The explanation benchmark's explainers: the search, the saliency methods (policy.methods)
in their order, and the floor."""
EXPLAIN_SHIFTS = tuple(s for s in SHIFTS if s != "other")
"""The shifts that plant a cause to name: every shift but "other"."""
EXPLAIN_WORLDS = PAPER_WORLDS

Condition = Literal[CONDITIONS]  # type: ignore[valid-type]


@dataclass(frozen=True)
class Q2Args:
    """Reproduce the paper's finetuning comparison: success against finetuning trajectories.

    For every world, shift, condition, budget and seed, one run takes the first task-irrelevant
    test task of that seed the base policy fails, the expert's demonstration of it, and a
    concept to mark task-irrelevant: NH-random a random concept for each variant; Baseline H,
    as the paper says, the right concept for each variant at the paper's rate of right answers
    without counterfactuals and a random wrong one otherwise (--baseline-h fixed: one answer per
    seed);
    CF H one who sees the loop's real diagnosis and names the right concept at the paper's
    rate with counterfactuals (never when the search found nothing or the wrong thing); Oracle
    always the right one. The budget is the number of finetuning trajectories: the
    demonstration plus budget - 1 distinct variants over the concept (same actions, edited
    states), repeated from the demonstration on when the concept has fewer variants. The
    adaptation is `dfa run`'s own (loop.adapt); both policies are scored on fresh tasks that
    carry the test task's shift, and on fresh tasks from all of what the user wants, on
    training layouts and (where the cause has enough) values no finetuning trajectory shows;
    runs.csv says how many distinct scenes they are and that none starts a finetuning one.

    Writes OUT/runs.csv (every run), OUT/table.md (means with 95% confidence intervals beside
    the paper's numbers, and CF H against Baseline H with one unit per seed: an exact test where
    enough seeds differ), OUT/plots/<world>-<shift>.png and
    OUT/curves.rrd. Runs already in OUT/runs.csv are skipped, so an interrupted experiment
    resumes where it stopped. The same seeds give the same runs.csv whichever backend ran them.
    """

    worlds: Annotated[tuple[Literal[PAPER_WORLDS], ...], tyro.conf.arg(aliases=("--world",))] = (
        PAPER_WORLDS
    )
    """Which of the paper's worlds."""
    shift: Literal[(*SHIFT_KINDS, "both")] = "both"  # type: ignore[valid-type]
    """object, distractor, or both."""
    budgets: tuple[int, ...] = PAPER_BUDGETS
    """Finetuning trajectories per run (the demonstration counts as one)."""
    seeds: int = 5
    """Seeds 0 .. SEEDS-1 (each picks a test task and every random choice of its runs)."""
    workers: int = 2
    """Runs executed side by side (processes locally, CPUs of a local Ray instance)."""
    backend: Literal["local", "ray"] = "local"
    """local (a process pool on this machine) or ray (pip install 'dfa[ray]')."""
    out: Path = Path("recordings/experiments/q2")
    """The results folder."""
    conditions: tuple[Condition, ...] = CONDITIONS
    """Which conditions."""
    max_size: int = 2
    """Largest edit the counterfactual search tries (CF H)."""
    baseline_h: Literal["paper", "fixed"] = "paper"
    """Baseline H's simulated user: "paper" (each augmented trajectory augments the right
    concept at the paper's rate of right answers, else a random wrong one) or "fixed" (one
    answer per seed: the right concept at that rate, else one wrong concept throughout)."""
    ray_address: str | None = None
    """An existing Ray cluster ("auto", "ray://host:10001"); default: start one here."""
    progress: bool = True
    """Show a progress bar."""
    finetuning: Annotated[Finetuning, tyro.conf.OmitArgPrefixes] = field(default_factory=Finetuning)
    """How every run finetunes and scores (its budget is one of --budgets)."""


@dataclass(frozen=True)
class ExplainArgs:
    """Measure how well each explanation names the planted cause of a failure.

    For every world, shift and seed, the first test task of that seed the base policy fails,
    its failed rollout and the expert's demonstration. Each explainer ranks the concepts the
    test scene shows: the counterfactual search (the concepts its best edit changes first);
    captum's Integrated Gradients, Occlusion, Grad-CAM and KernelSHAP over the failed
    rollout's frames against the demonstrated actions, reduced to the attribution inside each
    object's pixels, read four ways (the attribution's magnitude or its sign, over every step
    or the steps before the rollout diverges); a random order as the floor. A hit is the
    cause's object ranked first (object top-1, the headline), the planted cause ranked first
    (top-1) or among the first three (top-3).

    Writes OUT/tasks.csv (every task, explainer and readout), OUT/timings.csv, OUT/table.md
    (hit rates over distinct tasks with 95% Wilson intervals beside the paper's user
    accuracies, and time per task) and
    OUT/hits.png. Tasks already in OUT/tasks.csv are skipped, so an interrupted benchmark
    resumes where it stopped; the same seeds give the same tasks.csv on either backend.
    """

    worlds: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--world",))] = EXPLAIN_WORLDS
    """Which worlds (any that makes test tasks: `dfa worlds` says which)."""
    shifts: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--shift",))] = EXPLAIN_SHIFTS
    """Which shifts (those with a planted cause: object_ti, object_tr, distractor_ti, ...)."""
    tasks: int = 50
    """Tasks per world and shift: seeds 0 .. TASKS-1."""
    methods: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--method",))] = EXPLAINERS
    """Which explainers (counterfactual, integrated_gradients, occlusion, grad_cam, ...)."""
    workers: int = 2
    """Tasks explained side by side (processes locally, CPUs of a local Ray instance)."""
    backend: Literal["local", "ray"] = "local"
    """local (a process pool on this machine) or ray (pip install 'dfa[ray]')."""
    out: Path = Path("recordings/experiments/explain")
    """The results folder."""
    max_size: int = 2
    """Largest edit the counterfactual search tries."""
    ray_address: str | None = None
    """An existing Ray cluster ("auto", "ray://host:10001"); default: start one here."""
    progress: bool = True
    """Show a progress bar."""


@dataclass(frozen=True)
class PairArgs:
    """Can an explainer tell a policy thrown by a spurious concept from the same policy
    finetuned to ignore it? For each world, shift and seed, the world's base policy on its
    failing test task of the shift (a new distractor, distractor_ti; a recoloured or reshaped
    object, object_ti) and the policy the loop makes from it (TI feedback: variants over the
    cause's accepted values, finetuned): how far undoing the cause (the counterfactual's
    changes to it) moves each one's actions (the ground truth), and each saliency method's
    share of its attribution on the cause's pixels for each (by magnitude and of the blame).

    Writes OUT/pair.csv (a row per world, shift, seed, method and reading) and OUT/table.md
    (per world and shift: the behaviour per seed, the distinct test tasks, and per method and
    reading on how many seeds the base policy gets the larger share).
    """

    worlds: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--world",))] = ()
    """Which worlds (nav2d, doorkey; none named: both)."""
    shifts: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--shift",))] = (
        "distractor_ti",
        "object_ti",
    )
    """Which shifts (distractor_ti, object_ti)."""
    seeds: int = 10
    """Seeds 0 .. SEEDS-1 per world and shift, each an independent pair."""
    out: Path = Path("recordings/explain-pair")
    """Folder for pair.csv and table.md."""


@dataclass(frozen=True)
class UnplantedArgs:
    """The search, the saliency methods and the learned prior on failures nobody planted.

    Draws failing tasks the benchmark's generator did not make (search/unplanted.py): compound
    (a training task with two atomic changes of two different objects at once, drawn with the
    seed), moved (the same on the world's position shift) or natural (a training layout the
    policy fails with no edit at all: an outside agent's own failures). The ground truth is
    exhaustive: every edit of size 1 and 2 rolled out and judged by R'; the minimal edits that
    restore success. Measured on each task: whether the counterfactual search's best edit is
    one of them (its size, its rollouts), each saliency method's object top-1 against their
    objects, and the learned prior's rank of the first of them.

    Writes OUT/tasks.csv, OUT/saliency.csv, OUT/runs.json and OUT/table.md; a run replaces the
    rows of its world, policy and kind and keeps the others, and the table is rebuilt from all.
    """

    world: str = "nav2d"
    """Any world with training tasks (`dfa worlds`), e.g.
    minigrid:MiniGrid-DoorKey-5x5-v0:tile=12."""
    kind: Literal["compound", "moved", "natural"] = "compound"
    """Which failures: compound, moved (needs the world's 'other' shift) or natural."""
    tasks: int = 20
    """Failing tasks to measure (all distinct)."""
    seed: int = 0
    """Draws the candidates (seeds 1,000,000 x (SEED + 1) on) and the saliency's randomness."""
    policy: str | None = None
    """The policy (`sb3:FILE.zip`, a checkpoint folder, ...); default: the world's base policy."""
    prior: Path | None = None
    """A learned prior file (`dfa prior`); default: fitted here on --prior-tasks planted tasks."""
    prior_tasks: int = 20
    """Planted size-2 tasks the prior is fitted on when no --prior is given (0: no prior)."""
    prior_fit: Literal["planted", "others"] = "planted"
    """planted: the prior from --prior or --prior-tasks; others: each task's prior cross-fitted
    on the run's other tasks (their exhaustive ground truth; leave one out), for a world whose
    planted tasks are too rare to fit on (--prior-tasks is then unused)."""
    tries: int = 2000
    """Candidates drawn at most to find --tasks failing ones."""
    out: Path = Path("recordings/experiments/unplanted")
    """The results folder."""
