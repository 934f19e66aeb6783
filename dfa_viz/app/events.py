"""Applying session events to the loop state: live (after the event is on disk) and when a
session is replayed on resume. A computed value (the task, the demonstration, the search result,
the adaptation) is passed in live; on replay it is rebuilt from the event and its files."""

from __future__ import annotations

from typing import TYPE_CHECKING

from dfa_viz.app import work
from dfa_viz.app.demonstrate import input_for
from dfa_viz.app.run import Run, need
from dfa_viz.app.work import Adaptation
from sim.core import PRESENCE, Feedback, Label, UserError, World

if TYPE_CHECKING:
    from dfa_viz.app.state import LoopState


def apply_event(state: LoopState, ev: dict, computed=None) -> None:
    """Change the state as event `ev` says (its preconditions checked: UserError if unmet)."""
    kind = ev["type"]
    if kind == "task":
        world, task, rollout = computed or work.task_again(
            ev["world"], ev["shift"], ev["task_seed"], state.policies
        )
        state.world_name = world.name
        state.run = Run(world, ev["shift"], ev["seed"], task, rollout)
        state.demo_input = None
        # like `dfa run`'s <world>-<shift>-seed<seed>.rrd, plus the session and the line of
        # this task in its log: loading another task (or this one again) keeps this recording
        state.recording = state.out / (
            f"{world.name}-{ev['shift']}-seed{ev['seed']}-{state.session.folder.name}"
            f"-task{ev['_line']}.rrd"
        )
        state._recorded = -1
    elif kind == "judgement":
        run = need(state.run, "judge")
        run.failed = ev["failed"]
        if run.failed:
            state.demo_input = input_for(run.world, run.task)
    elif kind == "demonstration":
        run = need(state.run, "demonstrate")
        demo = computed or state.session.load_trajectory(ev["file"], ev)
        if demo.scenes[0] != run.task.scene or demo.horizon != run.world.horizon:
            raise UserError(f"{ev['file']} does not start from this task's scene")
        run.demo, run.demo_source = demo, ev["source"]
    elif kind == "search":
        run = need(state.run, "diagnose")
        if computed is None:
            result = work.search_from_json(ev)
            cfs = work.counterfactual_rollouts(
                run.world, state.policies.get(run.world), run.task, result
            )
        else:
            result, cfs = computed
        run.result, run.counterfactuals, run.tie = result, cfs, 0
    elif kind == "tie":
        run = need(state.run, "feedback", "adapted")
        n = min(len(run.result.counterfactuals), work.MAX_TIES) if run.result else 0
        if not 0 <= ev["index"] < n:
            raise UserError(f"tie {ev['index']} does not exist; there are {n}")
        run.tie = ev["index"]
    elif kind == "mark":
        run = need(state.run, "feedback", "adapted")
        run.marks[(ev["slot"], ev["concept"])] = label_of(run.world, ev)
    elif kind == "finetune":
        run = need(state.run, "feedback", "adapted")
        if computed is None:
            rollout = state.session.load_trajectory(ev["rollout_file"], ev)
            computed = Adaptation(
                Feedback.from_list(ev["feedback"]),
                ev["n_augmented"],
                tuple(float(v) for v in ev["losses"]),
                float(ev["success_before"]),
                float(ev["success_after"]),
                rollout,
            )
        run.adaptation = computed


def label_of(world: World, ev: dict) -> Label:
    if ev["label"] not in ("TI", "TR"):
        raise UserError(f"a mark is TI or TR, not {ev['label']!r}")
    slot = world.space.slot(ev["slot"])
    if ev["concept"] == PRESENCE:
        values: tuple[str, ...] = ("present", "absent")
    else:
        values = slot.concept(ev["concept"]).values
    bad = [v for v in ev["acceptable"] if v not in values]
    if bad:
        raise UserError(f"{ev['slot']}.{ev['concept']} has no {bad}; accepted: {', '.join(values)}")
    relevant = ev["label"] == "TR"
    return Label(ev["slot"], ev["concept"], relevant, () if relevant else tuple(ev["acceptable"]))
