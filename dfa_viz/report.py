"""The short human-readable report `dfa run` prints."""

from __future__ import annotations

from dfa_viz.loop import LoopReport


def format_report(r: LoopReport) -> str:
    t = r.task
    lines = [f'{r.world} / {t.shift} / seed {r.seed} (task {t.seed}): "{t.reward.instruction}"']
    if not r.failed:
        lines.append("  the policy succeeded: nothing to diagnose")
        return "\n".join(lines)
    lines.append("  failed: the base policy's rollout misses what the user wants")
    s = r.search
    if s is None or not s.found:
        tried = len(s.tried) if s else 0
        lines.append(
            f"  counterfactual: none found in {tried} edits — "
            "the cause is outside the concept space"
        )
    else:
        best, ties = s.counterfactuals[0], s.counterfactuals[1:]
        lines.append(f"  counterfactual (size {s.size}, {len(s.tried)} edits tried): {best.edit}")
        for c in ties:
            lines.append(f"    also minimal: {c.edit}")
    for lab in r.feedback.labels:
        kind = "TR" if lab.relevant else f"TI (acceptable: {', '.join(lab.acceptable)})"
        lines.append(f"  feedback: {lab.slot}.{lab.concept} is {kind}")
    loss = f", final loss {r.losses[-1]:.4f}" if r.losses else ""
    lines.append(f"  finetuned on 1 demonstration + {r.n_augmented} augmented{loss}")
    lines.append(
        f"  success on 10 fresh tasks from R': {r.success_before:.0%} -> {r.success_after:.0%}"
    )
    lines.append(f"  recording: {r.recording}")
    return "\n".join(lines)
