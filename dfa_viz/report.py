"""The short human-readable report `dfa run` prints, from the run's record."""

from __future__ import annotations

from dfa_viz.run_record import Evaluation, RunRecord
from search import SearchResult
from sim import get_world


def evaluation_sentence(ev: Evaluation, arrow: str = "->") -> str:
    """The evaluation in one sentence: success before and after adapting, on the fresh tasks
    with the shift and on those from all the user wants (the report's and the recording's)."""
    return (
        f"success on {len(ev.before.shifted)} fresh tasks with the shift: "
        f"{ev.before.on_shift:.0%} {arrow} {ev.after.on_shift:.0%} (on "
        f"{len(ev.before.overall)} from all you want: {ev.before.on_all:.0%} {arrow} "
        f"{ev.after.on_all:.0%}); {change_sentence(ev)}"
    )


def change_sentence(ev: Evaluation) -> str:
    """Which of the distinct fresh scenes with the shift changed, and how likely chance alone
    would rise as far (the exact one-sided McNemar test, Evaluation.change)."""
    ch = ev.change()
    return (
        f"of {ch.units} distinct, {ch.fixed} newly solved and {ch.broken} newly failed "
        f"(a rise this large by chance: p = {ch.p:.2g}, exact McNemar)"
    )


def closer_sentence(result: SearchResult) -> str:
    """Why a counterfactual was held closer to the demonstration than the bound asked for
    (SearchResult.tightened)."""
    return (
        f"the failed rollout never strayed {result.asked or 0.0:g} a step from the "
        "demonstration, so an edit had to keep the policy closer than it did: under "
        f"{result.epsilon or 0.0:.3f} a step"
    )


def format_report(r: RunRecord) -> str:
    t = r.task
    lines = [f'{r.world} / {r.shift} / seed {r.seed} (task {t.seed}): "{t.reward.instruction}"']
    world = get_world(r.world)
    space = world.space
    lines += [f"  note: {line}" for line in world.notes(t)]
    if not r.failed:
        lines.append("  the policy succeeded: nothing to diagnose")
        return "\n".join(lines)
    lines.append("  failed: the policy's rollout misses what the user wants")
    d = r.diagnosis
    if d is None or not d.result.found:
        tried = len(d.result.tried) if d else 0
        lines.append(
            f"  counterfactual: none found in {tried} edits — "
            "the cause is outside the concept space"
        )
    else:
        s = d.chosen()
        best, ties = s.counterfactuals[0], s.counterfactuals[1:]
        lines.append(f"  counterfactual (size {s.size}, {len(s.tried)} edits tried): {best.edit}")
        for c in ties:
            lines.append(f"    also minimal: {c.edit}")
        if s.tightened:
            lines.append(f"    {closer_sentence(s)}")
    for lab in r.feedback.labels:
        fine = space.describe(lab.slot, lab.concept, lab.acceptable)
        kind = "TR" if lab.relevant else f"TI (acceptable: {fine})"
        lines.append(f"  feedback: {lab.slot}.{lab.concept} is {kind}")
    ad, ev = r.adaptation, r.evaluation
    if ad is None and r.feedback.labels:
        lines.append(
            "  not adapted: this policy can be run but not trained (an ONNX graph); give a "
            "PyTorch, stable-baselines3 or own checkpoint to finetune it"
        )
    if ad is not None:
        loss = f", final loss {ad.losses[-1]:.4f}" if ad.losses else ""
        lines.append(
            f"  finetuned on {ad.budget} trajectories: the demonstration and "
            f"{len(ad.augmented)} variants{loss}"
        )
    if ev is not None:
        lines.append(f"  {evaluation_sentence(ev)}")
        if ev.fresh is not None:
            lines.append(f"  {ev.fresh.sentence()}")
    lines.append(f"  recording: {r.recording}")
    if r.dataset is not None:
        lines.append(f"  LeRobot dataset: {r.dataset}")
    return "\n".join(lines)
