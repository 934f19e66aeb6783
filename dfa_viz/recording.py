"""The Rerun recorder: one .rrd per run with every rollout, candidate, edit and curve."""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from datetime import timedelta
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from dfa_viz.loop import Evaluation, RunRecord
from search import Candidate, SearchResult
from sim.core import Edit, Feedback, Task, Trajectory, World, files

APP_ID = "dfa"
ROLLOUTS = ("failed", "demonstration", "counterfactual", "finetuned")
JPEG_QUALITY = 90
DETAIL_LIMIT = 300  # searches up to this size get one entity per candidate
DETAIL_BEST = 50  # larger ones: every candidate as a row, traces for the valid and best few


def recording_id(world: str, shift: str, seed: int) -> uuid.UUID:
    """The same run always gets the same recording id (reproducible files)."""
    return uuid.uuid5(uuid.NAMESPACE_URL, f"dfa/{world}/{shift}/{seed}")


def new_stream(rid: uuid.UUID, *, app_id: str = APP_ID) -> rr.RecordingStream:
    """A stream whose file holds the same content for the same calls, on any machine.

    No log time or tick columns; rows are cut into chunks by size and row count, never by a
    wall-clock tick, so the chunks are the same too. (Rerun's own row and chunk ids are
    time-based: two files of one run differ in those bytes only.)
    """
    # Rerun keeps every stream dropped so far (its two threads and every row it logged) until
    # this sweep, which rr.init also does; a server writes a file per action, so sweep here.
    rr.bindings.flush_and_cleanup_orphaned_recordings()
    rec = rr.RecordingStream(
        app_id,
        recording_id=rid,
        send_properties=False,
        batcher_config=rr.ChunkBatcherConfig(
            flush_tick=timedelta(days=1), flush_num_bytes=1 << 20, flush_num_rows=4096
        ),
    )
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    return rec


class RrdFile:
    """An .rrd written atomically: logged to a temporary file beside `path`, moved into place
    by `close()`; `close(keep=False)` (or an exception inside `with`) leaves `path` as it was."""

    def __init__(self, path: str | Path, rid: uuid.UUID, *, app_id: str = APP_ID) -> None:
        self.path = Path(path)
        self.tmp = files.temp_beside(self.path)
        self.rec = new_stream(rid, app_id=app_id)
        self.rec.save(self.tmp)

    def close(self, *, keep: bool = True) -> Path:
        self.rec.flush()
        self.rec.disconnect()
        if keep:
            files.commit(self.tmp, self.path)
        files.discard(self.tmp)
        return self.path

    def __enter__(self) -> rr.RecordingStream:
        return self.rec

    def __exit__(self, kind, value, tb) -> None:
        self.close(keep=kind is None)


def send_blueprint(rec: rr.RecordingStream, bp: rrb.Blueprint) -> None:
    """`rec.send_blueprint(bp)` (active and default), and the blueprint's stream closed after.

    Rerun 0.41's own send_blueprint logs the blueprint to a stream of its own that is never
    released (two threads and half a megabyte per call); disconnecting that stream frees it.
    """
    stream = rr.RecordingStream._from_native(
        rr.bindings.new_blueprint(
            application_id=rec.get_application_id(),
            make_default=False,
            make_thread_default=False,
            default_enabled=True,
        )
    )
    try:
        stream.set_time("blueprint", sequence=0)
        bp.to_blueprint()._log_to_stream(stream)
        storage = stream.memory_recording().storage
        rr.bindings.send_blueprint(storage, True, True, recording=rec.to_native())
    finally:
        stream.disconnect()


def blueprint(world: World) -> rrb.Blueprint:
    """Failed | demonstration | counterfactual | finetuned on one `step` timeline; the
    action-distance plot beneath; edit, feedback, loss and success at the bottom. Worlds with
    a 3D scene add their 3D views beside the camera images."""
    views: list = [rrb.Spatial2DView(origin=f"rollouts/{name}", name=name) for name in ROLLOUTS]
    if world.view3d is not None:
        from dfa_viz import scene3d

        views += scene3d.views()
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(*views),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="action_distance", name="action distance to the demo"),
                rrb.TimeSeriesView(origin="search/candidates", name="every candidate tried"),
            ),
            rrb.Horizontal(
                rrb.TextDocumentView(origin="edit", name="counterfactual edit"),
                rrb.TextDocumentView(origin="feedback", name="feedback"),
                rrb.TimeSeriesView(origin="finetune", name="finetuning loss"),
                rrb.BarChartView(origin="evaluation", name="success before / after"),
            ),
            row_shares=[3, 2, 2],
        ),
        collapse_panels=True,
    )


def edit_table(world: World, scene, edit: Edit) -> str:
    """Markdown before -> after table of an edit's concepts."""
    rows = ["| slot | concept | before | after |", "|---|---|---|---|"]
    rows += [f"| {c.slot} | {c.concept} | {c.old} | {c.new} |" for c in edit.ordered]
    return "\n".join(rows)


class Recorder:
    """Writes one run to an .rrd through an explicit RecordingStream (no global stream).

    `write_recording(path, world, record)` is the way in: it logs every part of a RunRecord in
    the loop's order and moves the file into place once it is whole.
    """

    def __init__(self, path: str | Path, world: World, task: Task) -> None:
        self.path = Path(path)
        self.world, self.task = world, task
        self.file = RrdFile(self.path, recording_id(world.name, task.shift, task.seed))
        self.rec = self.file.rec
        send_blueprint(self.rec, blueprint(world))
        self.rec.send_property(
            "task",
            rr.AnyValues(
                world=world.name,
                shift=task.shift,
                seed=task.seed,
                instruction=task.reward.instruction,
            ),
        )
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

    def _distance_to_demo(self, traj: Trajectory) -> np.ndarray:
        assert self._demo is not None
        a, b = traj.actions, self._demo.actions
        if self.world.discrete:
            return (a != b).astype(np.float64)
        return np.abs(a - b).sum(axis=1).astype(np.float64)  # (T,)

    # -- the parts of a run -------------------------------------------------------------------
    def rollout(self, name: str, traj: Trajectory) -> None:
        """Frames, per-dimension actions and success of one rollout on the `step` timeline;
        its action distance to the demonstration once that is logged."""
        self.rec.reset_time()
        for t, frame in enumerate(traj.observations):
            self.rec.set_time("step", sequence=t)
            self.rec.log(f"rollouts/{name}/frame", self._image(frame))
        actions = traj.actions.reshape(traj.horizon, -1).astype(np.float64)  # (T, A)
        steps = np.arange(traj.horizon)
        for k in range(actions.shape[1]):
            self._series(f"rollouts/{name}/action/{k}", steps, actions[:, k])
        self.rec.log(f"rollouts/{name}/success", rr.AnyValues(success=traj.success), static=True)
        if self.world.view3d is not None:
            from dfa_viz import scene3d

            scene3d.log_rollout(self.rec, self.world, name, traj)
        if name == "demonstration":
            self._demo = traj
        elif self._demo is not None and name in ("failed", "counterfactual", "finetuned"):
            self._series(f"action_distance/{name}", steps, self._distance_to_demo(traj))
        if name == "demonstration" and not self.world.discrete:
            eps = np.full(traj.horizon, self.world.epsilon)
            self._series("action_distance/epsilon", steps, eps)
            self.rec.log(
                "action_distance/epsilon",
                rr.SeriesLines(names="epsilon", colors=[128, 128, 128]),
                static=True,
            )

    def candidates(self, cands: Sequence[Candidate]) -> None:
        """Every candidate the search tried (the size of the search decides how)."""
        self.rec.reset_time()
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
            self.rec.log(
                "edit/delta", rr.TextDocument(text, media_type="text/markdown"), static=True
            )
            return
        lines = [edit_table(self.world, self.task.scene, result.best.edit)]
        if len(result.counterfactuals) > 1:
            lines.append(
                "\nOther minimal edits (ties): "
                + "; ".join(str(c.edit) for c in result.counterfactuals[1:])
            )
        self.rec.log(
            "edit/delta", rr.TextDocument("\n".join(lines), media_type="text/markdown"), static=True
        )
        space = self.world.space
        before = space.encode(self.task.scene).astype(np.float64)
        after = space.encode(self.world.apply(self.task.scene, result.best.edit)).astype(np.float64)
        self.rec.log("edit/phi_before", rr.BarChart(before), static=True)
        self.rec.log("edit/phi_after", rr.BarChart(after), static=True)

    def feedback(self, feedback: Feedback) -> None:
        rows = ["| slot | concept | label | acceptable |", "|---|---|---|---|"]
        for lab in feedback.labels:
            kind = "TR" if lab.relevant else "TI"
            rows.append(f"| {lab.slot} | {lab.concept} | {kind} | {', '.join(lab.acceptable)} |")
        self.rec.log(
            "feedback", rr.TextDocument("\n".join(rows), media_type="text/markdown"), static=True
        )

    def augmented(self, trajectories: Sequence[Trajectory]) -> None:
        self.rec.reset_time()
        for i, traj in enumerate(trajectories):
            for t, frame in enumerate(traj.observations):
                self.rec.set_time("step", sequence=t)
                self.rec.log(f"augmented/a{i:03d}/frame", self._image(frame))

    def losses(self, losses: Sequence[float]) -> None:
        self.rec.reset_time()
        self.rec.send_columns(
            "finetune/loss",
            indexes=[rr.TimeColumn("finetune_step", sequence=np.arange(len(losses)))],
            columns=rr.Scalars.columns(scalars=np.asarray(losses, np.float64)),
        )

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

    def close(self, *, keep: bool = True) -> None:
        """Finish the file and move it into place; `keep=False` (a run that failed) discards
        it and leaves an earlier recording at `path` untouched."""
        self.file.close(keep=keep)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, kind, value, tb) -> None:
        self.close(keep=kind is None)


def write_recording(path: str | Path, world: World, record: RunRecord) -> Path:
    """Write everything a run record holds to one .rrd, in the loop's order; the file at `path`
    is replaced only once the new one is whole."""
    with Recorder(path, world, record.task) as rec:
        if record.demo is not None:
            rec.rollout("demonstration", record.demo)
        rec.rollout("failed", record.rollout)
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
        if record.evaluation is not None:
            rec.evaluation(record.evaluation)
    return Path(path)
