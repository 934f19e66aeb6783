"""A run's recording read back with rerun's reader: DoorKey's actions by name, an ε line on
every world's distance plot, and view titles short enough to show whole."""

from __future__ import annotations

import re
from dataclasses import replace

import rerun as rr

from dfa_viz.loop import diagnose
from dfa_viz.recording import Recorder, write_recording
from dfa_viz.run_record import RunRecord
from policy import base_policy, failing_test_task
from search import SearchConfig
from sim import get_world
from sim.core import Feedback, Label

LONGEST_TITLE = 26  # characters: what a view a sixth of a 1280 px window wide shows whole


def strings(reader_stores) -> list[str]:
    """Every string value the stores hold (view names, series names, texts)."""
    out = []
    for store in reader_stores:
        for chunk in store.stream():
            for column in chunk.to_record_batch().to_pydict().values():
                stack = list(column)
                while stack:
                    v = stack.pop()
                    if isinstance(v, str):
                        out.append(v)
                    elif isinstance(v, list | tuple):
                        stack.extend(v)
                    elif isinstance(v, dict):
                        stack.extend(v.values())
    return out


def test_doorkey_recording_names_its_actions_draws_epsilon_and_cuts_no_title(tmp_path):
    world = get_world("doorkey")
    policy = base_policy(world)
    task, rollout = failing_test_task(world, policy, "object_ti", 0)
    demo = world.demonstrate(task)
    d = diagnose(world, policy, task, demo, config=SearchConfig.for_world(world))
    record = replace(
        RunRecord(world.name, "object_ti", 0, task, rollout, failed=True, demo=demo), diagnosis=d
    )
    path = write_recording(tmp_path / "run.rrd", world, record)
    reader = rr.chunk.RrdReader(path)
    data = reader.store()
    entities = {str(c.entity_path) for c in data.stream()}
    assert "/action_distance/epsilon" in entities, "the ε line, as on the other worlds"
    assert {f"/rollouts/failed/action/{k}" for k in range(6)} <= entities
    logged = strings([data])
    assert world.action_names == ("turn left", "turn right", "forward", "pick up", "drop", "toggle")
    assert "failed: forward" in logged and "failed: toggle" in logged
    assert not any("action (index)" in s for s in logged)
    shown = strings([reader.store(store=b) for b in reader.blueprints()])
    for name in (*world.action_names, "the policy ✗", "after the edit ✓", "distance to the demo"):
        assert name in shown, name
    titles = [s for s in shown if re.search(r"[a-z] [a-z]", s) and "/" not in s]
    assert titles and max(map(len, titles)) <= LONGEST_TITLE, max(titles, key=len)
    assert not any(s.startswith("action: ") for s in shown)


def test_the_feedback_and_edit_tables_are_narrow(tmp_path):
    """Short columns ("TI", "TR", "before → after"): a text view a third of the window wide
    shows every column."""
    world = get_world("nav2d")
    task = world.test_task("object_ti", 0)
    demo = world.demonstrate(task)
    record = RunRecord(world.name, "object_ti", 0, task, demo, failed=True, demo=demo)
    shapes = world.space.slot("goal").concept("shape").values
    labels = (Label("goal", "shape", False, shapes), Label("goal", "colour", True, ()))
    with Recorder(tmp_path / "t.rrd", world, record) as rec:
        rec.feedback(Feedback(labels))
    text = next(s for s in strings([rr.chunk.RrdReader(tmp_path / "t.rrd").store()]) if "|" in s)
    assert text.splitlines()[0] == "| concept | TI/TR | accepts |"
    assert "| goal.colour | TR | |" in text and "| goal.shape | TI | all " in text
    assert max(len(line) for line in text.splitlines()) <= 40
