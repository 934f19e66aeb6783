"""`dfa experiment explain`: how well each explanation names the planted cause of a failure.

One job per (world, shift, seed), a pure function of it and the settings (and the committed
base policy):
1. The task: the first test task of the seed's stream that the base policy fails
   (policy.failing_test_task), its failed rollout, and the scripted expert's demonstration.
2. The ground truth: the planted cause `task.cause`, as a person names it (its user concept,
   "goal.shape", "lava.presence": every lava tile a distractor shift adds is one answer).
3. Every explainer ranks the concepts visible in the test scene (sim.core.visible):
   counterfactual  the search (search.counterfactual_search; search.ranking.concept_ranking)
   integrated_gradients, occlusion, grad_cam, kernel_shap   captum's maps of the failed
                   rollout against the demonstration, reduced to the attribution inside each
                   object's pixels (policy.concept_saliency)
   random          a seeded random order: the floor
4. Per explainer one row: where the cause ranks, top-1 and top-3 hits, and whether the first
   concept belongs to the cause's object (the object-level reading a map can give). A saliency
   method has a row per readout of its one set of maps (policy.concept_saliency): the
   attribution's magnitude ("abs") or its sign ("signed": the object that pushes the action
   away from the demonstration most first), over every explained step ("all") or the steps
   before the rollout leaves the demonstration ("before"); the search and the random order have
   one row (reading and span "-"). `task_id` names the task's scene and cause, so that tables
   count distinct tasks (several seeds can draw one task; TI and TR tasks share scenes).
5. Per saliency readout, against the ground-truth mask (policy.saliency_metrics): the share of
   the map's mass (the magnitude, or the positive blame) on the cause's pixels (`mass_cause`,
   Quantus' relevance mass accuracy) and on pixels of no object (`mass_off`), the cause's share
   of the pixels (`area_cause`: a uniform map's relevance mass), the deletion score of the
   action distance with pixels deleted in the readout's order (`deletion`; the random order's
   row: pixels in random order), and the cascading randomisation's Spearman correlations, top
   layer first, on the first `sanity_steps` steps (`randomised`). Not timed as the
   explainer's cost.
The benchmark as a whole (its plan, running it, its table and plot) is explain_run.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import socket
import time
from dataclasses import asdict, dataclass, field

from dfa_viz.experiment.args import EXPLAINERS
from policy.methods import METHOD_NAMES, METHODS

READINGS = ("abs", "signed")  # policy.concept_saliency's, written here without torch
SPANS = ("all", "before")
READOUTS = tuple((r, s) for r in READINGS for s in SPANS)
"""A saliency method's readouts, (reading, span), in the order tables list them."""
NONE = "-"
"""Reading and span of the explainers that have one reading (the search, the random order)."""


def explainer_names() -> dict[str, str]:
    """Each explainer's name in tables and plots (the saliency methods' are policy.methods')."""
    return {"counterfactual": "Counterfactual search", **METHOD_NAMES, "random": "Random"}


# the columns of tasks.csv, in order; the first four are a row's key
COLUMNS = (
    "world",
    "shift",
    "seed",
    "explainer",
    "reading",
    "span",
    "task_seed",
    "task_id",
    "cause",
    "rank",
    "hit1",
    "hit3",
    "object_hit1",
    "n_concepts",
    "n_steps",
    "ranking",
    "mass_cause",
    "mass_off",
    "area_cause",
    "deletion",
    "randomised",
)
KEY = COLUMNS[:6]
TIMING_COLUMNS = (*COLUMNS[:4], "duration_s", "host")
"""A timing is per explainer and task: every readout of a method comes from one set of maps."""


def readouts_of(explainer: str) -> tuple[tuple[str, str], ...]:
    """The (reading, span) rows an explainer has per task."""
    return READOUTS if explainer in METHODS else ((NONE, NONE),)


def task_id(task) -> str:
    """12 hex digits naming a task's scene and planted cause."""
    text = json.dumps({"scene": task.scene.to_dict(), "cause": task.cause}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class ExplainSettings:
    """What every job of one explanation benchmark shares; a results folder keeps to one set."""

    explainers: tuple[str, ...] = EXPLAINERS
    """Which explainers rank the concepts."""
    max_size: int = 2
    """Largest edit the counterfactual search tries."""
    saliency: dict = field(default_factory=dict)
    """policy.saliency.SaliencyConfig fields that differ from its defaults."""
    sanity_steps: int = 4
    """The randomisation check's steps (the first ones of the failed rollout; 0: none)."""

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True, order=True)
class TaskSpec:
    """One job: the failing test task of `seed` in `world` under `shift`."""

    world: str
    shift: str
    seed: int

    @property
    def key(self) -> tuple[str, str, int]:
        return (self.world, self.shift, self.seed)


@functools.lru_cache(maxsize=3)
def _policy(world_name: str):
    from policy import base_policy
    from sim import get_world

    return base_policy(get_world(world_name))


def _rng(spec: TaskSpec, what: str):
    import numpy as np

    from policy.variants import stable_int

    return np.random.default_rng([spec.seed, stable_int(what, spec.world, spec.shift)])


def explain_task(spec: TaskSpec, settings: ExplainSettings = ExplainSettings()) -> dict:
    """Every explainer on one task: {"rows": tasks.csv rows (strings), "timings": their
    timings.csv rows (wall seconds of each explainer on this task, what it needs included:
    the search; the saliency methods' maps plus the object masks they share)}."""
    from policy import failing_test_task
    from policy.concept_saliency import frame_maps, prepare, readouts
    from policy.saliency import SaliencyConfig
    from policy.saliency_metrics import deletion_curve, deletion_score, randomised
    from search import SearchConfig, counterfactual_search
    from search.ranking import concept_ranking
    from sim import get_world
    from sim.core.visible import shown_slots, visible_concepts

    world, policy = get_world(spec.world), _policy(spec.world)
    task, rollout = failing_test_task(world, policy, spec.shift, spec.seed)
    demo = world.demonstrate(task)
    assert task.cause is not None, f"{spec.shift} tasks have no planted cause"
    cause = world.space.user_concept(*task.cause).name
    visible = visible_concepts(world.space, task.scene)
    objects = {uc.name: shown_slots(uc, task.scene) for uc in visible}
    config = SaliencyConfig(**settings.saliency)
    frames, frames_s = None, 0.0
    host = f"{socket.gethostname()}:{os.getpid()}"
    rows, timings = [], []
    tid = task_id(task)
    for explainer in settings.explainers:
        t0 = time.perf_counter()
        rankings: dict[tuple[str, str], tuple[str, ...]] = {}
        steps: dict[tuple[str, str], int | str] = {(NONE, NONE): NONE}
        metrics: dict[tuple[str, str], dict[str, str]] = {
            (NONE, NONE): dict.fromkeys(MASK_COLUMNS, NONE)
        }
        if explainer == "counterfactual":
            result = counterfactual_search(
                world,
                policy,
                task.scene,
                demo,
                config=SearchConfig.for_world(world, max_size=settings.max_size),
                task=task,
            )
            rankings[(NONE, NONE)] = concept_ranking(world.space, task.scene, result)
        elif explainer == "random":
            order = _rng(spec, "random-ranking").permutation(len(visible))
            rankings[(NONE, NONE)] = tuple(visible[int(i)].name for i in order)
            if frames is None:
                frames = prepare(world, task, rollout, demo)
            noise = _rng(spec, "random-deletion").random(frames.masks.shape[1:])
            curve = deletion_curve(policy, frames.obs, frames.actions, noise)
            metrics[(NONE, NONE)]["deletion"] = _number(deletion_score(curve))
        else:
            if frames is None:
                frames = prepare(world, task, rollout, demo)
                frames_s = time.perf_counter() - t0
                t0 = time.perf_counter()
            seed = int(_rng(spec, explainer).integers(2**31))
            unsigned, signed = frame_maps(policy, frames, explainer, seed=seed, config=config)
            for key, ranking in readouts(frames, unsigned, signed, seed=seed).items():
                rankings[key] = ranking.concepts
                steps[key] = frames.steps(key[1])
            t0 -= frames_s  # the masks are part of every saliency method's cost
        duration = time.perf_counter() - t0
        if explainer not in ("counterfactual", "random"):
            n = min(settings.sanity_steps, len(frames.obs))
            rho = randomised(
                policy,
                frames.obs[:n],
                frames.actions[:n],
                explainer,
                features=frames.features[:n] if explainer == "kernel_shap" else None,
                seed=seed,
                config=config,
            )
            for key in rankings:
                metrics[key] = _against_the_mask(frames, cause, unsigned, signed, *key, policy)
                metrics[key]["randomised"] = " ".join(_number(r) for r in rho[key[0]])
        assert tuple(rankings) == readouts_of(explainer), "readouts and readouts_of disagree"
        for (reading, span), ranking in rankings.items():
            rank = ranking.index(cause) + 1 if cause in ranking else 0
            row = {
                "world": spec.world,
                "shift": spec.shift,
                "seed": spec.seed,
                "explainer": explainer,
                "reading": reading,
                "span": span,
                "task_seed": task.seed,
                "task_id": tid,
                "cause": cause,
                "rank": rank,
                "hit1": int(rank == 1),
                "hit3": int(1 <= rank <= 3),
                "object_hit1": int(bool(ranking) and objects[ranking[0]] == objects[cause]),
                "n_concepts": len(visible),
                "n_steps": steps[(reading, span)],
                "ranking": " ".join(ranking),
                **metrics[(reading, span)],
            }
            assert tuple(row) == COLUMNS, "row and COLUMNS disagree"
            rows.append({k: str(v) for k, v in row.items()})
        timings.append(
            {
                **{k: str(row[k]) for k in TIMING_COLUMNS[:4]},
                "duration_s": f"{duration:.4f}",
                "host": host,
            }
        )
    return {"rows": rows, "timings": timings}


MASK_COLUMNS = COLUMNS[COLUMNS.index("mass_cause") :]
"""The columns measured against the ground-truth mask ("-" where an explainer has no map)."""


def _number(x: float) -> str:
    return "nan" if x != x else f"{x:.4f}"


def _against_the_mask(frames, cause: str, unsigned, signed, reading, span, policy) -> dict:
    """One readout's mass on the cause and off every object, and its deletion score."""
    import numpy as np

    from policy.concept_saliency import reading_map
    from policy.saliency_metrics import deletion_curve, deletion_score, relevance_mass

    n = frames.steps(span)
    k = [c.name for c in frames.concepts].index(cause)
    score = reading_map(unsigned, signed, reading)[:n]  # (n, H, W): magnitude or blame
    mass = np.clip(score, 0, None)
    curve = deletion_curve(policy, frames.obs[:n], frames.actions[:n], score)
    return {
        "mass_cause": _number(relevance_mass(mass, frames.masks[k, :n])),
        "mass_off": _number(relevance_mass(mass, frames.features[:n] == 0)),
        "area_cause": _number(float(frames.masks[k, :n].mean())),
        "deletion": _number(deletion_score(curve)),
        "randomised": NONE,
    }
