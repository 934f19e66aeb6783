"""A run of the loop as LeRobot episodes: one per trajectory, with dfa's own columns.

Each trajectory (T actions, T + 1 observations) becomes an episode of T frames, frame t being
observation t and action t; the task is the instruction. Columns of dfa's own, per frame:

    dfa.role             demonstration, variant, counterfactual, failed or finetuned
    dfa.edit             the concept edit that made the episode's scene: the counterfactual's
                         minimal edit, a variant's changes from the demonstration it was made
                         from (slot.concept: old -> new; ...); "" for the others
    dfa.concept          the concepts that edit changes (slot.concept, space-separated)
    dfa.label            the user's TI/TR mark of each of them, in the same order ("" unmarked)
    dfa.action_distance  the step's action distance to the user's demonstration (L1, or 0/1 for
                         discrete actions); -1 on steps the demonstration does not have
    dfa.scene            the frame's scene (JSON, sim.core.Scene.to_dict): a dataset dfa wrote
                         is read back into trajectories, and its episodes checked as
                         demonstrations, from these
    dfa.run              which run the episode belongs to (world, shift, seed; a sweep's or an
                         experiment's key)
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np

from dfa_viz.run_record import RunRecord
from search import distance_to_demo
from sim.core import PRESENCE, Change, Edit, Feedback, Scene, Task, Trajectory, World
from sim.lerobot import Episode

ROLES = ("demonstration", "variant", "counterfactual", "failed", "finetuned")
COLUMNS = (
    "dfa.role",
    "dfa.edit",
    "dfa.concept",
    "dfa.label",
    "dfa.action_distance",
    "dfa.scene",
    "dfa.run",
)
NO_STEP = -1.0  # dfa.action_distance where the demonstration has no such step


def episode(
    world: World,
    traj: Trajectory,
    task: Task,
    *,
    role: str,
    run: str,
    demo: Trajectory | None = None,
    edit: Edit | None = None,
    feedback: Feedback = Feedback(),
) -> Episode:
    """One trajectory as an episode of traj.horizon frames."""
    assert role in ROLES, f"role is one of {ROLES}, not {role!r}"
    t = traj.horizon
    if demo is None or role in ("demonstration", "variant"):
        distance = np.zeros(t, np.float32)  # a variant keeps its source's actions
    else:
        d = distance_to_demo(world, traj, demo)  # (T,) NaN past the demonstration
        distance = np.where(np.isnan(d), NO_STEP, d).astype(np.float32)
    changes = edit.ordered if edit is not None else ()
    marks = {(lab.slot, lab.concept): lab for lab in feedback.labels}

    def mark(c: Change) -> str:
        lab = marks.get((c.slot, c.concept))
        return "" if lab is None else ("TR" if lab.relevant else "TI")

    def same(text: str) -> np.ndarray:
        return np.array([text] * t, dtype=object)

    return Episode(
        task.reward.instruction,
        traj.observations[:t],
        traj.actions,
        bool(traj.success),
        {
            "dfa.role": same(role),
            "dfa.edit": same("" if edit is None or not changes else str(edit)),
            "dfa.concept": same(" ".join(f"{c.slot}.{c.concept}" for c in changes)),
            "dfa.label": same(" ".join(mark(c) for c in changes).strip()),
            "dfa.action_distance": distance,
            "dfa.scene": np.array(
                [json.dumps(s.to_dict(), separators=(",", ":")) for s in traj.scenes[:t]],
                dtype=object,
            ),
            "dfa.run": same(run),
        },
    )


def edit_between(a: Scene, b: Scene) -> Edit:
    """The concept changes that take scene `a` to scene `b` (presence, and the looks of objects
    present in `b`); positions are not concepts and are not compared."""
    changes = []
    for oa in a.objects:
        ob = b.obj(oa.slot)
        if oa.present != ob.present:
            old, new = ("present", "absent") if oa.present else ("absent", "present")
            changes.append(Change(oa.slot, PRESENCE, old, new))
        if ob.present:
            changes += [
                Change(oa.slot, c, v, ob.value(c)) for c, v in oa.values if ob.value(c) != v
            ]
    return Edit.of(*changes)


def variant_source(variant: Trajectory, sources: Sequence[Trajectory]) -> Trajectory | None:
    """The demonstration a variant was made from: the same actions, the agent and every object
    present in both where the source has them."""
    for src in sources:
        same_actions = src.actions.shape == variant.actions.shape and np.array_equal(
            src.actions, variant.actions
        )
        a, b = src.scenes[0], variant.scenes[0]
        if (
            same_actions
            and a.agent == b.agent
            and all(
                o.pos == b.obj(o.slot).pos for o in a.objects if o.present and b.obj(o.slot).present
            )
        ):
            return src
    return None


def run_name(record: RunRecord) -> str:
    return f"{record.world} {record.shift} seed {record.seed}"


def run_episodes(
    world: World,
    record: RunRecord,
    *,
    known: Sequence[Trajectory] = (),
    run: str | None = None,
) -> list[Episode]:
    """Every trajectory of a run, in the order demonstration, variants, counterfactuals,
    failed, finetuned; `known`: the base policy's training demonstrations, which variants may
    be made from (a variant from none of them and not from the demonstration has no dfa.edit)."""
    run = run if run is not None else run_name(record)
    task, demo, fb = record.task, record.demo, record.feedback
    out: list[Episode] = []

    def add(traj: Trajectory, role: str, edit: Edit | None = None) -> None:
        out.append(
            episode(world, traj, task, role=role, run=run, demo=demo, edit=edit, feedback=fb)
        )

    if demo is not None:
        add(demo, "demonstration")
    if record.adaptation is not None:
        srcs = [demo, *known] if demo is not None else list(known)
        for v in record.adaptation.augmented:
            src = variant_source(v, srcs)
            add(v, "variant", None if src is None else edit_between(src.scenes[0], v.scenes[0]))
    if record.diagnosis is not None:
        d = record.diagnosis
        order = [d.tie, *(i for i in range(len(d.counterfactuals)) if i != d.tie)]
        for i in order:  # the one the user looked at first, then the other ties
            if i < len(d.counterfactuals) and i < len(d.result.counterfactuals):
                add(d.counterfactuals[i], "counterfactual", d.result.counterfactuals[i].edit)
    if record.failed:
        add(record.rollout, "failed")
    if record.adaptation is not None:
        add(record.adaptation.rollout, "finetuned")
    return out
