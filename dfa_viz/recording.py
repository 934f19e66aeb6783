"""The Rerun recorder: one .rrd per run with every rollout, candidate, edit and curve."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr

from dfa_viz import charts
from dfa_viz.charts import rgb
from dfa_viz.layout import action_labels, action_series, blueprint
from dfa_viz.overlay import SaliencyLayer, heat_rgba
from dfa_viz.report import closer_sentence, evaluation_sentence
from dfa_viz.rrd import RrdFile, recording_id, send_blueprint
from dfa_viz.run_record import Evaluation, RunRecord
from policy.methods import METHOD_NAMES
from search import Candidate, SearchResult, distance_to_demo
from sim.core import Edit, Feedback, Trajectory, World

JPEG_QUALITY = 90
DETAIL_LIMIT = 300  # searches up to this size get one entity per candidate
DETAIL_BEST = 50  # larger ones: every candidate as a row, traces for the valid and best few
SALIENCY_ORDER = 10.0  # draw order of the saliency layer: above the frame (images default -10)


def edit_table(edit: Edit) -> str:
    """Markdown before -> after table of an edit's concepts."""
    rows = ["| concept | before → after |", "|---|---|"]
    rows += [f"| {c.slot}.{c.concept} | {c.old} → **{c.new}** |" for c in edit.ordered]
    return "\n".join(rows)


def task_text(record: RunRecord) -> str:
    """The task as a reviewer reads it: world, shift, seeds, instruction, outcome."""
    t = record.task
    lines = [
        f"## {record.world} · {record.shift} · seed {record.seed}",
        f"**What the user wants:** {t.reward.instruction}",
        f"(test task {t.seed} of seed {record.seed}: the first task of the seed that the base "
        "policy fails)",
        "",
        f"- the policy: {'did it ✓' if record.rollout.success else 'failed ✗'}",
    ]
    if record.demo is not None:
        lines.append(f"- demonstration: {record.demo_source or 'given'}")
    d = record.diagnosis
    if d is not None:
        found = d.edit is not None
        lines.append(
            f"- counterfactual: {d.edit}"
            if found
            else "- no counterfactual: the cause is outside the concept space"
        )
    ev = record.evaluation
    if ev is not None:
        lines.append(f"- {evaluation_sentence(ev, '→')}")
        if ev.fresh is not None:
            lines.append(f"- {ev.fresh.sentence()}")
    return "\n".join(lines)


class Recorder:
    """Writes one run to an .rrd through an explicit RecordingStream (no global stream).

    `write_recording(path, world, record)` is the way in: it logs every part of a RunRecord in
    the loop's order and moves the file into place once it is whole.
    """

    def __init__(
        self,
        path: str | Path,
        world: World,
        record: RunRecord,
        *,
        saliency: SaliencyLayer | None = None,
    ) -> None:
        self.path = Path(path)
        self.world, self.task = world, record.task
        task = record.task
        self.file = RrdFile(self.path, recording_id(world.name, task.shift, task.seed))
        self.rec = self.file.rec
        self.rec.send_recording_name(f"{record.world} · {record.shift} · seed {record.seed}")
        method = saliency.method if saliency is not None else None
        send_blueprint(self.rec, blueprint(world, record, saliency=method))
        self.rec.send_property(
            "task",
            rr.AnyValues(
                world=world.name,
                shift=task.shift,
                seed=record.seed,
                task_seed=task.seed,
                instruction=task.reward.instruction,
            ),
        )
        self._markdown("task", task_text(record))
        self._demo: Trajectory | None = None

    # -- helpers ------------------------------------------------------------------------------
    def _image(self, frame: np.ndarray):
        img = rr.Image(frame)
        return img if self.world.lossless_frames else img.compress(JPEG_QUALITY)

    def _series(self, entity: str, steps: np.ndarray, values: np.ndarray, timeline: str = "step"):
        keep = ~np.isnan(values)
        if keep.any():
            self.rec.send_columns(
                entity,
                indexes=[rr.TimeColumn(timeline, sequence=steps[keep])],
                columns=rr.Scalars.columns(scalars=values[keep].astype(np.float64)),
            )

    def _markdown(self, entity: str, text: str) -> None:
        self.rec.log(entity, rr.TextDocument(text, media_type="text/markdown"), static=True)

    def _chart(self, name: str, image: np.ndarray) -> None:
        self.rec.log(f"charts/{name}", rr.Image(image), static=True)

    def _pixel(self, x: float, y: float) -> tuple[float, float]:
        """A point in the world's coordinates on its rendered frame, in pixels."""
        x0, x1, y0, y1 = self.world.image_extent  # type: ignore[misc]
        h, w = self.world.obs_shape[:2]
        return (x - x0) / (x1 - x0) * w, (y1 - y) / (y1 - y0) * h

    # -- the parts of a run -------------------------------------------------------------------
    def rollout(self, name: str, traj: Trajectory) -> None:
        """Frames, per-dimension actions and success of one rollout on the `step` timeline;
        its action distance to the demonstration once that is logged."""
        self.rec.reset_time()
        for t, frame in enumerate(traj.observations):
            self.rec.set_time("step", sequence=t)
            self.rec.log(f"rollouts/{name}/frame", self._image(frame))
        if self.world.demo_input == "pick_place":  # the pick and place points on the frame
            self._pick_place(name, traj)
        actions = action_series(self.world, traj.actions)  # (T, A)
        steps = np.arange(traj.horizon)
        labels = action_labels(self.world)
        for k in range(actions.shape[1]):
            entity = f"rollouts/{name}/action/{k}"
            self._series(entity, steps, actions[:, k])
            label = labels[min(k, len(labels) - 1)]
            series = rr.SeriesLines(names=f"{name}: {label}", colors=rgb(name))
            self.rec.log(entity, series, static=True)
        self.rec.log(f"rollouts/{name}/success", rr.AnyValues(success=traj.success), static=True)
        if self.world.view3d is not None:
            from dfa_viz import scene3d

            scene3d.log_rollout(self.rec, self.world, name, traj)
        if name == "demonstration":
            self._demo = traj
        elif self._demo is not None and name in ("failed", "counterfactual", "finetuned"):
            entity = f"action_distance/{name}"
            self._series(entity, steps, distance_to_demo(self.world, traj, self._demo))
            self.rec.log(entity, rr.SeriesLines(names=name, colors=rgb(name)), static=True)
        if name == "demonstration":  # every world's bound, DoorKey's 0 included
            self._bound("epsilon", self.world.epsilon, "ε (the search's bound)")

    def _bound(self, key: str, value: float, label: str) -> None:
        """A bound as a flat line over the demonstration's steps, in both distance plots."""
        steps = np.arange(self._demo.horizon) if self._demo is not None else np.arange(1)
        for entity in (f"action_distance/{key}", f"search/{key}"):
            self._series(entity, steps, np.full(len(steps), value))
            self.rec.log(entity, rr.SeriesLines(names=label, colors=rgb("epsilon")), static=True)

    def _pick_place(self, name: str, traj: Trajectory) -> None:
        """The pick point, the place point and an arrow between them, over the first frame."""
        a = np.asarray(traj.actions, np.float64).reshape(-1)[:4]
        (u0, v0), (u1, v1) = self._pixel(a[0], a[1]), self._pixel(a[2], a[3])
        colour = rgb(name)
        self.rec.set_time("step", sequence=0)
        self.rec.log(
            f"rollouts/{name}/action",
            rr.Arrows2D(
                origins=[(u0, v0)],
                vectors=[(u1 - u0, v1 - v0)],
                colors=[[255, 255, 255]],
                radii=0.6,
            ),
        )
        self.rec.log(
            f"rollouts/{name}/points",
            rr.Points2D([(u0, v0), (u1, v1)], colors=[colour, [255, 255, 255]], radii=1.5),
        )
        self.rec.reset_time()

    def saliency(self, layer: SaliencyLayer) -> None:
        """The failed rollout's saliency maps as a heat-coloured RGBA image over its frames
        (`rollouts/failed/saliency`, on `step`, drawn above the frame), cleared at the first
        step without a map; the method in the recording's properties."""
        self.rec.send_property(
            "saliency",
            rr.AnyValues(
                method=layer.method,
                name=METHOD_NAMES.get(layer.method, layer.method),
                explains="-|pi(s) - a_demo| (continuous) or the demonstrated action's logit",
            ),
        )
        entity = "rollouts/failed/saliency"
        for t, rgba in enumerate(heat_rgba(layer.maps)):  # (H, W, 4) uint8
            self.rec.set_time("step", sequence=t)
            self.rec.log(entity, rr.Image(rgba, color_model="RGBA", draw_order=SALIENCY_ORDER))
        self.rec.set_time("step", sequence=len(layer.maps))
        self.rec.log(entity, rr.Clear(recursive=False))
        self.rec.reset_time()

    def distances(self, record: RunRecord) -> None:
        """One-step worlds: each rollout's distance to the demonstration as a bar."""
        if self.world.horizon != 1 or record.demo is None:
            return
        bars = {"failed": record.rollout}
        if record.diagnosis is not None and record.diagnosis.counterfactual is not None:
            bars["counterfactual"] = record.diagnosis.counterfactual
        if record.adaptation is not None:
            bars["finetuned"] = record.adaptation.rollout
        values = {
            k: float(np.nansum(distance_to_demo(self.world, v, record.demo)))
            for k, v in bars.items()
        }
        self._chart("distance", charts.distance_bars(values, self.world.epsilon))

    def candidates(self, cands: Sequence[Candidate]) -> None:
        """Every candidate the search tried (the size of the search decides how)."""
        self.rec.reset_time()
        if self.world.horizon == 1 and cands:
            self._chart(
                "candidates",
                charts.candidates_chart(
                    [c.total for c in cands], [c.valid for c in cands], self.world.epsilon
                ),
            )
        if len(cands) <= DETAIL_LIMIT:
            for i, cand in enumerate(cands):
                self._log_candidate(i, cand)
            return
        # A large search: one row per candidate on the `candidate` timeline ...
        index = np.arange(len(cands))
        self.rec.send_columns(
            "search/all",
            indexes=[rr.TimeColumn("candidate", sequence=index)],
            columns=[
                *rr.Scalars.columns(scalars=np.array([c.total for c in cands])),
                *rr.AnyValues.columns(
                    edit=[str(c.edit) for c in cands],
                    size=[c.edit.size for c in cands],
                    valid=[c.valid for c in cands],
                    dropped_at=[-1 if c.dropped_at is None else c.dropped_at for c in cands],
                ),
            ],
        )
        # ... and the distance traces of the valid ones and the closest others.
        best = sorted(index, key=lambda i: (not cands[i].valid, cands[i].total))[:DETAIL_BEST]
        for i in sorted(set(best) | {i for i in index if cands[i].valid}):
            self._log_candidate(int(i), cands[i])

    def _log_candidate(self, index: int, cand: Candidate) -> None:
        entity = f"search/candidates/c{index:05d}"
        self.rec.log(
            entity,
            rr.AnyValues(
                edit=str(cand.edit),
                size=cand.edit.size,
                valid=cand.valid,
                dropped_at=-1 if cand.dropped_at is None else cand.dropped_at,
                total_distance=cand.total,
            ),
            static=True,
        )
        colour = [40, 200, 70] if cand.valid else [200, 60, 60]
        self.rec.log(entity, rr.SeriesLines(names=str(cand.edit), colors=[colour]), static=True)
        self._series(entity, np.arange(len(cand.distances)), cand.distances.astype(np.float64))

    def search(self, result: SearchResult) -> None:
        """The search's summary, the chosen edit as a before -> after table, and Phi of both."""
        self.rec.reset_time()
        self.rec.log("search/summary", rr.TextDocument(result.summary()), static=True)
        if result.best is None:
            text = (
                "**No counterfactual found** — the cause is outside the concept space "
                f"(tried {len(result.tried)} edits of up to {result.max_size} changes)."
            )
            self._markdown("edit/delta", text)
            return
        lines = [
            "The smallest change to the scene after which the policy does what the "
            f"demonstration does ({len(result.tried)} edits tried):",
            "",
            edit_table(result.best.edit),
        ]
        if len(result.counterfactuals) > 1:
            lines += ["", "Other changes as small that work too:"]
            lines += [f"- {c.edit}" for c in result.counterfactuals[1:]]
        if result.tightened:  # held under less than ε: that bound drawn too
            lines += ["", closer_sentence(result).capitalize() + "."]
            self._bound("bound", result.epsilon or 0.0, f"the bound here: {result.epsilon:.3f}")
        self._markdown("edit/delta", "\n".join(lines))
        space = self.world.space
        before = space.encode(self.task.scene).astype(np.float64)
        after = space.encode(self.world.apply(self.task.scene, result.best.edit)).astype(np.float64)
        self.rec.log("edit/phi_before", rr.BarChart(before), static=True)
        self.rec.log("edit/phi_after", rr.BarChart(after), static=True)

    def feedback(self, feedback: Feedback) -> None:
        space = self.world.space
        rows = ["| concept | TI/TR | accepts |", "|---|---|---|"]
        for lab in feedback.labels:
            if lab.relevant:
                rows.append(f"| {lab.slot}.{lab.concept} | TR | |")
            else:
                fine = space.describe(lab.slot, lab.concept, lab.acceptable)
                rows.append(f"| {lab.slot}.{lab.concept} | TI | {fine} |")
        self._markdown("feedback", "\n".join(rows))

    def augmented(self, trajectories: Sequence[Trajectory]) -> None:
        self.rec.reset_time()
        for i, traj in enumerate(trajectories):
            for t, frame in enumerate(traj.observations):
                self.rec.set_time("step", sequence=t)
                self.rec.log(f"augmented/a{i:03d}/frame", self._image(frame))
        self.rec.reset_time()

    def losses(self, losses: Sequence[float]) -> None:
        """The loss per finetuning step: as a chart (seen on every timeline) and as values on
        the `finetune_step` timeline."""
        self.rec.reset_time()
        if not losses:
            return
        self.rec.send_columns(
            "finetune/loss",
            indexes=[rr.TimeColumn("finetune_step", sequence=np.arange(len(losses)))],
            columns=rr.Scalars.columns(scalars=np.asarray(losses, np.float64)),
        )
        self._chart("loss", charts.loss_chart(losses))

    def evaluation(self, ev: Evaluation) -> None:
        self.rec.reset_time()
        values = [ev.before.on_shift, ev.after.on_shift, ev.before.on_all, ev.after.on_all]
        self.rec.log("evaluation/success", rr.BarChart(np.array(values)), static=True)
        self.rec.log(
            "evaluation/values",
            rr.AnyValues(
                before=ev.before.on_shift,
                after=ev.after.on_shift,
                all_before=ev.before.on_all,
                all_after=ev.after.on_all,
            ),
            static=True,
        )
        self._chart(
            "success",
            charts.success_chart(
                (ev.before.on_shift, ev.before.on_all),
                (ev.after.on_shift, ev.after.on_all),
                len(ev.before.shifted),
            ),
        )

    def close(self, *, keep: bool = True) -> None:
        """Finish the file and move it into place; `keep=False` (a run that failed) discards
        it and leaves an earlier recording at `path` untouched."""
        self.file.close(keep=keep)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, kind, value, tb) -> None:
        self.close(keep=kind is None)


def write_recording(
    path: str | Path, world: World, record: RunRecord, *, saliency: SaliencyLayer | None = None
) -> Path:
    """Write everything a run record holds to one .rrd, in the loop's order; the file at `path`
    is replaced only once the new one is whole. saliency: a layer over the failed rollout's
    frames (dfa_viz.overlay.failed_saliency)."""
    with Recorder(path, world, record, saliency=saliency) as rec:
        if record.demo is not None:
            rec.rollout("demonstration", record.demo)
        rec.rollout("failed", record.rollout)
        if saliency is not None:
            rec.saliency(saliency)
        d = record.diagnosis
        if d is not None:
            rec.candidates(d.result.tried)
            rec.search(d.chosen())
            if d.counterfactual is not None:
                rec.rollout("counterfactual", d.counterfactual)
        ad = record.adaptation
        if ad is not None:
            rec.feedback(ad.feedback)
            rec.augmented(ad.augmented)
            rec.losses(ad.losses)
            rec.rollout("finetuned", ad.rollout)
        rec.distances(record)
        if record.evaluation is not None:
            rec.evaluation(record.evaluation)
    return Path(path)
