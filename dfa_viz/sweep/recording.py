"""The sweep's recording: the heatmap, a bar chart per concept, the ranking, and the worst few
edited rollouts each beside its task's unedited one on the `step` timeline.

    sweep/heatmap                     every single edit's failure rate minus the control's
                                      (the same tasks unedited) (static image)
    sweep/concepts/<slot>.<concept>   each value's difference, 95% interval (static image)
    sweep/summary                     the ranking: concepts, worst edits, interactions (text)
    rollouts/worstK/unedited, .../edited
                                      the K-th worst edit's example task, frames and actions
                                      on `step` as the run recorder logs a rollout
"""

from __future__ import annotations

import uuid
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from dfa_viz.recording import Recorder
from dfa_viz.rrd import RrdFile, send_blueprint
from dfa_viz.sweep.figures import Heatmap, concept_bars, concept_names
from search.sweep import SweepCell, SweepResult, failure_task, task_of
from sim.core import World

APP_ID = "dfa-sweep"


def recording_id(result: SweepResult) -> uuid.UUID:
    """The same sweep always gets the same recording id."""
    seeds = ",".join(map(str, result.seeds))
    return uuid.uuid5(uuid.NAMESPACE_URL, f"dfa/sweep/{result.world}/{result.policy}/{seeds}")


def worst_cells(result: SweepResult, k: int) -> list[SweepCell]:
    """The k most damaging single edits that have an example, on distinct tasks and slots
    where there are enough."""
    with_example = [c for c in result.cells if c.example is not None and c.failures]
    picked: list[SweepCell] = []
    for c in with_example:
        if len(picked) == k:
            break
        if all((p.slot, p.concept) != (c.slot, c.concept) for p in picked):
            picked.append(c)
    for c in with_example:  # fewer concepts than k: fill with the next most damaging edits
        if len(picked) == k:
            break
        if c not in picked:
            picked.append(c)
    return picked


class SweepRecorder(Recorder):
    """The run recorder's rollout logging, under a sweep's own header."""

    def __init__(self, path: Path, world: World, result: SweepResult) -> None:
        self.path, self.world, self.task = Path(path), world, None
        self.file = RrdFile(self.path, recording_id(result), app_id=APP_ID)
        self.rec = self.file.rec
        self._demo = None
        self.rec.send_recording_name(f"sweep · {result.world} · {result.policy}")


def blueprint(world: World, names: list[tuple[str, str]], worst: list[SweepCell]) -> rrb.Blueprint:
    pairs = [
        rrb.Vertical(
            rrb.Spatial2DView(origin=f"rollouts/worst{k}/unedited", name=f"unedited · seed {ex}"),
            rrb.Spatial2DView(origin=f"rollouts/worst{k}/edited", name=f"{c.label} ✗"),
        )
        for k, (c, ex) in enumerate((c, c.example.seed) for c in worst)  # type: ignore[union-attr]
    ]
    bars = [rrb.Spatial2DView(origin=f"sweep/concepts/{s}.{c}", name=f"{s}.{c}") for s, c in names]
    top = rrb.Horizontal(
        rrb.Spatial2DView(origin="sweep/heatmap", name="failure rate of every edit - unedited"),
        rrb.TextDocumentView(origin="sweep/summary", name="ranking"),
        column_shares=[3, 2],
    )
    rows: list = [top]
    if pairs:
        rows.append(rrb.Horizontal(*pairs))
    if world.horizon > 1 and worst:
        rows.append(rrb.TimeSeriesView(origin="rollouts", name="actions of the rollouts shown"))
    if bars:
        rows.append(rrb.Tabs(*bars, name="per concept"))
    return rrb.Blueprint(
        rrb.Vertical(*rows),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=False,
    )


def summary_text(result: SweepResult, shown: int = 15) -> str:
    lines = [
        f"## sweep · {result.world} · {result.policy}",
        f"{len(result.cells)} single edits on {result.tasks} tasks ({result.distinct} distinct); "
        f"the policy fails {result.base_failures} of the distinct ones unedited. Trials are "
        "distinct starting scenes; the difference is from the same tasks unedited. Concepts "
        "and edits are ranked by that difference, largest first (then by how often they fail).",
        "",
        "| # | concept | fails | unedited | difference (95% CI) | trials |",
        "|---|---|---|---|---|---|",
    ]
    for i, c in enumerate(result.concepts):
        rate = "—" if not c.n else f"{c.failure_rate:.0%}"
        control = "—" if not c.n else f"{c.control_rate:.0%}"
        lines.append(
            f"| {i + 1} | {c.slot}.{c.concept} | {rate} | {control} | {_diff(c)} | {c.n} |"
        )
    lines += [
        "",
        "| # | edit | fails | 95% CI | unedited | difference (95% CI) | deviation |",
        "|---|---|---|---|---|---|---|",
    ]
    for i, c in enumerate(result.cells[:shown]):
        if c.n:
            lo, hi = c.failure_ci
            lines.append(
                f"| {i + 1} | {c.label} | {c.failure_rate:.0%} | {lo:.0%}–{hi:.0%} | "
                f"{c.control_rate:.0%} | {_diff(c)} | {c.deviation:.3f} |"
            )
    if result.interactions:
        lines += [
            "",
            "**Pairs that fail more often than both alone**, ranked by how much more often "
            "than the worse of the two alone, largest first",
            "",
        ]
        lines += [
            f"- {p.label}: {p.failure_rate:.0%} (alone at most {p.singles_rate:.0%})"
            for p in result.interactions[:shown]
        ]
    return "\n".join(lines)


def _diff(c) -> str:
    if not c.n:
        return "—"
    lo, hi = c.difference_ci
    return f"{100 * c.difference:+.0f} ({100 * lo:+.0f} to {100 * hi:+.0f})"


def write_sweep_recording(
    path: Path, world: World, policy, result: SweepResult, *, heatmap: Heatmap, worst: int = 4
) -> Path:
    """One .rrd of the sweep, moved into place once whole."""
    cells = worst_cells(result, worst)
    names = list(concept_names(result))
    with SweepRecorder(path, world, result) as r:
        send_blueprint(r.rec, blueprint(world, names, cells))
        r.rec.send_property(
            "sweep",
            rr.AnyValues(
                world=result.world,
                policy=result.policy,
                tasks=result.tasks,
                distinct=result.distinct,
                rollouts=result.rollouts,
            ),
        )
        r.rec.log("sweep/heatmap", rr.Image(heatmap.image), static=True)
        r.rec.log(
            "sweep/summary",
            rr.TextDocument(summary_text(result), media_type="text/markdown"),
            static=True,
        )
        for slot, concept in names:
            bars = concept_bars(result, slot, concept)
            if bars is not None:
                r.rec.log(f"sweep/concepts/{slot}.{concept}", rr.Image(bars), static=True)
        for k, c in enumerate(cells):
            ex = c.example
            assert ex is not None
            unedited = task_of(world, ex.seed)
            edited = failure_task(world, ex)
            r.rollout(f"worst{k}/unedited", world.rollout(unedited, policy))
            r.rollout(f"worst{k}/edited", world.rollout(edited, policy))
    return Path(path)
