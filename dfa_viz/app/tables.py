"""The page's words: what to do now, the diagnosis, what changed, the adaptation results."""

from __future__ import annotations

from dfa_viz.app.view import View
from dfa_viz.report import change_sentence, closer_sentence
from sim.core import Edit, Scene, World

NO_COUNTERFACTUAL = "No counterfactual found — the cause is outside the concept space."

STATUS = {
    "pick": "Pick a world, a shift and a seed, then **Load task** (or **Next task**).",
    "judge": (
        "Watch the policy's rollout (the *failed* column: press ▶ play or drag the slider). "
        "Did it do what you wanted?"
    ),
    "solved": "You judged the rollout a success: nothing to diagnose. Load another task.",
    "demonstrate": "Show what you wanted: demonstrate it here, or ask the scripted expert.",
    "diagnose": "Searching for the smallest concept edit that makes the policy do what you showed…",
    "feedback": "Mark each edited concept TI or TR, then **Augment & finetune**.",
    "adapted": "Adapted. Compare the finetuned rollout with the failed one, or load another task.",
}


def status_text(view: View) -> str:
    run = view.record
    text = STATUS[view.stage]
    if run is not None:
        text = f"**Task:** “{run.task.reward.instruction}”  \n{text}"
    if view.stage == "feedback" and run is not None and run.edit is None:
        text = f"**{NO_COUNTERFACTUAL}**  \nYou can still finetune on the demonstration alone."
    if view.job is not None:
        text += f"  \n*{view.job.text}*"
    return text


def diagnosis_text(view: View) -> str:
    run = view.record
    if run is None or run.diagnosis is None:
        return "Searching…" if view.stage == "diagnose" else ""
    res = run.diagnosis.result
    succeeds = res.criterion == "succeeds"
    if not res.found:
        goal = "do the task" if succeeds else "follow the demonstration"
        return (
            f"**{NO_COUNTERFACTUAL}**  \nNo edit of up to {res.max_size} concept changes makes "
            f"the policy {goal} ({len(res.tried)} edits tried): what changed "
            "is something the concepts do not describe (e.g. a position)."
        )
    n = len(res.counterfactuals)
    changes = f"{res.size} change{'s' if res.size > 1 else ''}"
    does = "does the task you demonstrated" if succeeds else "follows your demonstration"
    text = (
        f"**Counterfactual found** ({len(res.tried)} edits tried). The policy {does} "
        f"when the scene is edited like this ({changes}):"
    )
    if res.tightened:
        text += f"  \n({closer_sentence(res).capitalize()}.)"
    if n > 1:
        other = "another edit" if n == 2 else f"{n - 1} other edits"
        text += f"  \n{other} as small work{'s' if n == 2 else ''} too: pick one to look at below."
    if view.world is not None and view.world.view3d is not None:
        text += "  \nIn 3D: solid = the scene as it was, wireframe = after the edit."
    return text


def edit_table(world: World, scene: Scene, edit: Edit) -> str:
    """What changed: a before → after table of the edited concepts."""
    rows = ["| object | concept | before → after |", "|---|---|---|"]
    rows += [f"| {c.slot} | {c.concept} | {c.old} → **{c.new}** |" for c in edit.ordered]
    return "\n".join(rows)


def strip(solved: tuple[bool, ...]) -> str:
    """Per fresh task, solved or not: ✓✓✗✓…"""
    return "".join("✓" if s else "✗" for s in solved)


def results_text(view: View) -> str:
    run = view.record
    if run is None:
        return ""
    ad, ev = run.adaptation, run.evaluation
    if ad is None:
        if run.unmarked():
            return "Mark " + ", ".join(run.unmarked()) + " first."
        return ""
    labels = "; ".join(
        f"{lab.slot}.{lab.concept} {'TR' if lab.relevant else 'TI'}" for lab in ad.feedback.labels
    )
    text = (
        f"Finetuned on {ad.budget} trajectories: the demonstration and "
        f"{len(ad.augmented)} variants" + (f" ({labels})" if labels else "") + "."
    )
    if ev is not None:
        text += (
            f"  \n**Success on {len(ev.before.shifted)} fresh tasks with the shift: "
            f"{ev.before.on_shift:.0%} → {ev.after.on_shift:.0%}**  \n"
            f"before `{strip(ev.before.shifted)}`  \nafter  `{strip(ev.after.shifted)}`  \n"
            f"Paired, {change_sentence(ev)}.  \n"
            f"On {len(ev.before.overall)} fresh tasks from everything you want (the training "
            f"looks too): {ev.before.on_all:.0%} → {ev.after.on_all:.0%}"
            + (f"  \nHow fresh: {ev.fresh.sentence()}." if ev.fresh else "")
        )
    return (
        text + "  \nThe *finetuned* column shows the new policy on this task"
        f" ({'succeeds' if ad.rollout.success else 'still fails'})."
    )
