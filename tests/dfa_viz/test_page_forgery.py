"""Control values and actions the feedback page never offered, sent over its own WebSocket
by a PageWire client (page_wire.py: viser's protocol as the browser speaks it, with the page's
Origin), and stale or forged calls on the page's state: each refused in one line before
anything is written. The server is `start` in this process; every wait is for what the page
shows, its ceiling only ends a hang.
"""

from __future__ import annotations

import pytest
from page_wire import CEILING_S, PageWire, same_page, session_events

from dfa_viz.app.feedback import TI, TR
from dfa_viz.app.page import ASK_EXPERT
from sim.core import UserError


# -- forged control values ------------------------------------------------------------------------
def _refused(tab: PageWire, label: str, kind: str, value) -> str:
    """Send `value` for the control `label` (shown or not) as a forged message; the one line
    the tab is told."""
    uuids = tab.find(label, kind, shown=False)
    assert len(uuids) == 1, (label, kind)
    n = len(tab.notes)
    tab.update(uuids[0], value=value)
    tab.wait(lambda: len(tab.notes) > n, f"the refusal of {label} = {value!r}", CEILING_S)
    assert len(tab.notes) == n + 1, tab.notes[n:]
    return tab.notes[-1]


def test_forged_control_values_are_refused_in_one_line_and_never_acted_on(served, capfd):
    app, folder = served
    tab, other = PageWire(app.url), PageWire(app.url)
    try:
        for t in (tab, other):
            t.wait_enabled("Load task")
        for label, kind, value in [
            ("world", "Dropdown", "minigrid:MiniGrid-Empty-5x5-v0"),  # registered, not offered
            ("world", "Dropdown", "mars"),
            ("shift", "Dropdown", "sweep"),  # a shift only the Sweep tab's failures have
            ("shift", "Dropdown", "nonsense\nwith a second line"),
            ("seed", "Number", -1),
            ("seed", "Number", 2**40),
            ("tasks", "Number", 10**6),  # the Sweep tab's number of training tasks
            ("tasks", "Number", 0),
            ("speed", "Dropdown", "1000×"),
            ("saliency", "Dropdown", "everything"),
            ("step", "Slider", 10**6),
            ("step", "Slider", -3),
            ("minimal edit", "Dropdown", "1. goal.colour: red → blue"),  # hidden: no edit yet
        ]:
            note = _refused(tab, label, kind, value)
            assert note.startswith(f"Refused: {label} ") and "\n" not in note, note
        assert other.notes == []  # only the tab that sent them is told

        # refused before viser reads them (one line each, on the server): a control update
        # that sets anything but the value, a value no control takes, a frame that is not a
        # message; and a plain value of the wrong type, which viser's own cast refuses
        world, shift, seed = (tab.one(x) for x in ("world", "shift", "seed"))
        tab.update(world, options=["nav2d", "mars"])
        tab.update(shift, update_cb=0)
        tab.update(seed, value=float("nan"))
        tab.send({"type": "NoSuchMessage"})
        tab.ws.send(b"\xc1 not msgpack")
        tab.update(seed, value="abc")
        # the tab's controls work on as before: an offered value is taken without a word
        tab.update(shift, value="object_ti")
        tab.wait(
            lambda: any(p.task.shift.value == "object_ti" for p in app.pages.values()),
            "the offered shift taken",
            CEILING_S,
        )
        tab.update(shift, value="distractor_ti")
        # forged values and Load pressed at once: the task is the one the page offered
        n = len(tab.notes)
        tab.update(world, value="mars")
        tab.update(seed, value=-7)
        tab.click("Load task")
        tab.wait(lambda: len(tab.notes) == n + 2, "the two refusals", CEILING_S)
        tab.wait_enabled("Failed", CEILING_S)
        assert [e["type"] for e in session_events(folder)] == ["session", "task"]
        task = session_events(folder)[1]
        assert (task["world"], task["shift"], task["seed"]) == ("nav2d", "distractor_ti", 0)
        assert app.state.sweep is None  # no sweep ran
        same_page(tab, other)  # and neither tab shows a forged value

        # at the feedback: a press on a control that is not offered now, a hidden checkbox
        tab.click("Failed")
        tab.click(ASK_EXPERT)
        tab.wait(lambda: tab.find(TR, "Button"), "the feedback controls", CEILING_S)
        note = _refused(tab, "Succeeded", "Button", True)  # judged already: disabled
        assert note == "Refused: Succeeded is not offered now"
        tab.click(TR)
        tab.wait(lambda: "right to care" in tab.text(), "the TR mark", CEILING_S)
        (edited,) = app.state.record.edit.ordered
        values = app.state.snapshot().world.space.values(edited.slot, edited.concept)
        note = _refused(tab, values[-1], "Checkbox", False)  # shown only while marked TI
        assert note == f"Refused: {values[-1]} is not offered now"
        tab.click(TI)
        tab.wait(lambda: "variants may take" in tab.text(), "the TI mark", CEILING_S)
        mark = session_events(folder)[-1]
        assert mark["type"] == "mark" and mark["acceptable"] == list(values)
        # the page's own changes (new ties, new options) are never taken for a tab's
        assert sum("minimal edit" in note for note in tab.notes) == 1
        assert other.notes == []
    finally:
        tab.close()
        other.close()
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err, (out + err)[-3000:]
    refusals = [x for x in out.splitlines() if "refused a message" in x]
    for why in ("sets options", "sets update_cb", "finite number", "KeyError", "Decode", "'abc'"):
        assert sum(why in x for x in refusals) == 1, (why, refusals)


def test_stale_or_forged_actions_are_refused_before_they_are_written(served, tmp_path):
    """Through the state itself (what any tab's press comes to): values the page does not
    offer, a mark of a concept the edit does not change, a tie that does not exist. None is
    written, so the session still resumes."""
    from dfa_viz.app.server import open_state, wait_idle

    app, folder = served
    state = app.state
    for call, words in [
        (lambda: state.pick("minigrid:MiniGrid-Empty-5x5-v0", "object_ti", 0), "no world"),
        (lambda: state.pick("nav2d", "sweep", 0), "no shift 'sweep'"),
        (lambda: state.pick("nav2d", "object_ti", -1), "seed must be"),
        (lambda: state.run_sweep("nav2d", 10**6), "1 to 500 tasks"),
        (lambda: state.run_sweep("mars", 5), "no world 'mars'"),
    ]:
        with pytest.raises(UserError, match=words):
            call()
    assert state.jobs.current is None and state.sweep is None
    state.pick("nav2d", "distractor_ti", 0)
    wait_idle(state, timeout_s=CEILING_S)
    state.judge(True)
    state.demonstrate(expert=True)
    wait_idle(state, timeout_s=CEILING_S)
    log = (folder / "session.jsonl").read_bytes()
    with pytest.raises(UserError, match="not an edited concept"):
        state.mark("goal", "colour", relevant=True, acceptable=())
    with pytest.raises(UserError, match="has no"):
        state.mark("distractor", "presence", relevant=False, acceptable=("sideways",))
    with pytest.raises(UserError, match="tie 7 does not exist"):
        state.select_tie(7)
    assert (folder / "session.jsonl").read_bytes() == log
    app.stop()
    again = open_state(session=folder, out=tmp_path / "rec")
    try:
        assert again.snapshot().stage == "feedback"
    finally:
        again.close()
