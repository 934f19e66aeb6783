"""Sessions on disk: durable appends, resume, and clear errors for malformed folders."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dfa_viz.app import events as E
from dfa_viz.app import replay as R
from dfa_viz.app.sessions import LOG, Session, SessionError, read_events
from dfa_viz.configs import AdaptConfig
from sim.core import Obj, Scene, Trajectory
from sim.core.task import MAX_SEED
from sim.registry import world_names


def _snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file's bytes and mtime: to show that reading touched nothing."""
    return {
        str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _write(folder: Path, *lines: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOG
    path.write_text("".join(line + "\n" for line in lines))
    return path


HEADER = json.dumps({"type": "session", "version": 1, "world": "nav2d"})
TASK = json.dumps(
    {"type": "task", "world": "nav2d", "shift": "object_ti", "seed": 0, "task_seed": 3}
)


def test_appends_are_on_disk_and_resume(tmp_path):
    s = Session.open(tmp_path / "s", world="nav2d")
    assert s.append(E.TaskLoaded("nav2d", "object_ti", 0, 3)) == 2
    assert s.append(E.Judged(True)) == 3
    s.close()
    lines = (tmp_path / "s" / LOG).read_text().splitlines()
    assert [json.loads(x)["type"] for x in lines] == ["session", "task", "judgement"]
    again = Session.open(tmp_path / "s", world="doorkey")
    assert again.world == "nav2d"  # the session's own world wins
    assert again.replay() == [(2, E.TaskLoaded("nav2d", "object_ti", 0, 3)), (3, E.Judged(True))]
    assert again.replay() == []  # handed out once: no event stays in memory
    again.close()


def test_typed_events_round_trip_through_json():
    from policy.evaluate import Score
    from search import SearchResult
    from sim.core import Feedback, Label

    label = Label("goal", "shape", False, ("X", "square"))
    events = [
        E.TaskLoaded("doorkey", "distractor_ti", 3, 601),
        E.Judged(False),
        E.Demonstrated("demo-0004.npz", "keys"),
        E.Searched(SearchResult((), (), None, 2, complete=False)),
        E.TieChosen(1),
        E.Marked(label),
        E.Marked(Label("distractor", "presence", True)),
        E.Finetuned(
            Feedback((label,)),
            24,
            (0.5, 0.25),
            "finetuned-0009.npz",
            "policy-0009",
            AdaptConfig(budget=7),
            Score((True, False), (True, True)),
            Score((True, True), (True, True)),
        ),
    ]
    for ev in events:
        line = json.dumps({"type": ev.TYPE, **ev.to_json()}, allow_nan=False)
        assert E.from_json(json.loads(line)) == ev, ev


def test_a_finetune_event_of_an_older_session_still_loads():
    """Written before scores and the adaptation's settings were kept."""
    old = {
        "type": "finetune",
        "feedback": [{"slot": "goal", "concept": "shape", "label": "TI", "acceptable": ["X"]}],
        "n_augmented": 3,
        "losses": [0.1, 0.05],
        "success_before": 0.5,
        "success_after": 1.0,
        "rollout_file": "finetuned-0006.npz",
        "policy_dir": "policy-0006",
        "time": "2026-11-30T10:00:00",
    }
    ev = E.from_json(old)
    assert isinstance(ev, E.Finetuned) and ev.before is None and ev.config is None
    assert ev.n_augmented == 3 and ev.losses == (0.1, 0.05)


def test_applying_events_needs_no_threads_or_browser(nav, nav_policy):
    """Each event returns a new record; a precondition not met is a UserError."""
    from dfa_viz.run_record import RunRecord
    from sim.core import UserError

    task = nav.test_task("object_ti", 1)
    demo = nav.demonstrate(task)
    rebuild = R.Rebuild(
        policy=lambda w: nav_policy,
        trajectory=lambda name: demo,
        checkpoint=lambda name, w: nav_policy,
    )
    r = R.apply(None, E.TaskLoaded("nav2d", "object_ti", 0, 1), rebuild)
    assert isinstance(r, RunRecord) and r.stage == "judge" and r.task == task
    with pytest.raises(UserError, match="the loop is at 'judge'"):
        R.apply(r, E.Demonstrated("demo.npz", "expert"), rebuild)
    r2 = R.apply(r, E.Judged(True), rebuild)
    assert r.stage == "judge" and r2.stage == "demonstrate"
    r3 = R.apply(r2, E.Demonstrated("demo.npz", "expert"), rebuild)
    assert r3.stage == "diagnose" and r3.demo is demo


@pytest.mark.parametrize(
    ("bad", "expected"),
    [
        ("{not json", "not a JSON line"),
        ('{"type": "dance"}', "unknown event type 'dance'; accepted: session, task"),
        ('{"type": ["task"]}', 'unknown event type ["task"]; accepted: session, task'),
        ('{"type": "judgement"}', "judgement event without 'failed'"),
        ('{"type": "judgement", "failed": "yes"}', "judgement.failed must be bool"),
        (
            '{"type": "task", "world": "nav2d", "shift": "x", "seed": true, "task_seed": 1}',
            "task.seed must be int",
        ),
        ("[1, 2]", "expected a JSON object"),
        ("[" * 200_000, "not a JSON line (nested too deeply)"),
        ('{"type": "tie", "index": 1' + "0" * 5000 + "}", "not a JSON line (a number with too"),
        (
            '{"type": "task", "world": "nav2d", "shift": "object_ti", "seed": 0, "task_seed": -1}',
            f"task.task_seed must be an integer from 0 to {MAX_SEED}, not -1",
        ),
        (
            '{"type": "task", "world": "nav2d", "shift": "object_ti", "seed": -1, "task_seed": 1}',
            f"task.seed must be an integer from 0 to {MAX_SEED}, not -1",
        ),
        (
            '{"type": "task", "world": "mars", "shift": "object_ti", "seed": 0, "task_seed": 1}',
            "task.world: unknown world 'mars'; accepted: nav2d, doorkey, tabletop",
        ),
        (
            '{"type": "task", "world": "nav2d", "shift": "up", "seed": 0, "task_seed": 1}',
            "task.shift: unknown shift 'up'; accepted: object_ti,",
        ),
        ('{"type": "tie", "index": -2}', "tie.index must not be negative, got -2"),
    ],
)
def test_malformed_line_names_file_and_line_and_touches_nothing(tmp_path, bad, expected):
    folder = tmp_path / "s"
    path = _write(folder, HEADER, TASK, bad, '{"type": "judgement", "failed": true}')
    (folder / "demo-0003.npz").write_bytes(b"keep me")
    before = _snapshot(folder)
    with pytest.raises(SessionError) as err:
        Session.open(folder, world="nav2d")
    assert f"{path}:3:" in str(err.value)
    assert expected in str(err.value)
    assert _snapshot(folder) == before  # no lock file, no rewrite, nothing


def test_header_is_checked(tmp_path):
    _write(tmp_path / "a", TASK)
    with pytest.raises(SessionError, match=r"session.jsonl:1: the first line must be"):
        Session.open(tmp_path / "a", world="nav2d")
    _write(tmp_path / "b", json.dumps({"type": "session", "version": 9, "world": "nav2d"}))
    with pytest.raises(SessionError, match=r":1: session format version 9"):
        Session.open(tmp_path / "b", world="nav2d")
    _write(tmp_path / "c")
    with pytest.raises(SessionError, match=r":1: empty session log"):
        Session.open(tmp_path / "c", world="nav2d")


def test_a_header_naming_an_unknown_world_is_refused_at_open(tmp_path):
    path = _write(tmp_path / "s", json.dumps({"type": "session", "version": 1, "world": "mars"}))
    before = _snapshot(tmp_path / "s")
    with pytest.raises(SessionError) as err:
        Session.open(tmp_path / "s", world="nav2d")
    assert str(err.value).startswith(
        f"{path}:1: session.world: unknown world 'mars'; accepted: nav2d, doorkey, tabletop"
    )
    assert _snapshot(tmp_path / "s") == before
    with pytest.raises(SessionError, match="unknown world 'mars'"):
        Session.open(tmp_path / "new", world="mars")  # a new session: nothing is created
    assert not (tmp_path / "new").exists()


def test_line_cut_short_by_a_crash_is_dropped_and_cut_on_append(tmp_path):
    folder = tmp_path / "s"
    path = _write(folder, HEADER, TASK)
    with open(path, "ab") as f:
        f.write(b'{"type": "judgement", "fai')  # the process died mid-write
    entries, _, notes = read_events(folder)
    assert [type(e).__name__ for _, e in entries] == ["SessionStarted", "TaskLoaded"]
    assert notes and f"{path}:3: incomplete last line" in notes[0]
    s = Session.open(folder, world="nav2d")
    s.append(E.Judged(False))
    s.close()
    lines = path.read_text().splitlines()
    assert len(lines) == 3 and json.loads(lines[2])["failed"] is False


def test_a_last_line_without_its_newline_was_cut_short_even_if_it_parses(tmp_path):
    """A line goes to disk whole with its newline: one without it was never acknowledged, even
    where the crash cut it right before the newline and what is there parses."""
    folder = tmp_path / "s"
    path = folder / LOG
    folder.mkdir()
    path.write_text(HEADER + "\n" + TASK)  # no trailing newline
    entries, size, notes = read_events(folder)
    assert [type(e).__name__ for _, e in entries] == ["SessionStarted"]
    assert size == len(HEADER) + 1
    assert notes and f"{path}:2: incomplete last line" in notes[0]
    s = Session.open(folder, world="nav2d")
    s.append(E.Judged(True))
    s.close()
    assert [json.loads(x)["type"] for x in path.read_text().splitlines()] == [
        "session",
        "judgement",
    ]


def test_one_server_per_session(tmp_path):
    s = Session.open(tmp_path / "s", world="nav2d")
    with pytest.raises(SessionError, match="open in another running server"):
        Session.open(tmp_path / "s", world="nav2d")
    s.close()
    Session.open(tmp_path / "s", world="nav2d").close()  # free again once closed


def test_files_named_by_events(tmp_path):
    s = Session.open(tmp_path / "s", world="nav2d")
    scene = Scene("nav2d", (Obj("goal", True, (("colour", "red"),), (5.0, -5.0)),), (0.0, 0.0, 0.0))
    traj = Trajectory(
        (scene, scene), np.zeros((2, 4, 4, 3), np.uint8), np.zeros((1, 2), np.float32), False
    )
    name = s.save_trajectory(traj, "demo")
    line = s.append(E.Demonstrated(name, "clicks"))
    assert s.load_trajectory(name, line).equals(traj)
    with pytest.raises(SessionError, match=r"session.jsonl:2: '../x.npz' is not a file name"):
        s.file("../x.npz", line)
    (s.folder / name).write_bytes(b"garbage")
    with pytest.raises(
        SessionError, match=rf"session.jsonl:2: the file it names is unusable: .*{name}"
    ):
        s.load_trajectory(name, line)
    s.close()


def test_events_out_of_order_name_the_line(tmp_path):
    from dfa_viz.app.state import LoopState

    folder = tmp_path / "s"
    path = _write(folder, HEADER, '{"type": "judgement", "failed": true}')
    before = _snapshot(folder)
    session = Session.open(folder, world="nav2d")
    with pytest.raises(SessionError, match=rf"{path}:2: pick a task first"):
        LoopState(session, out=tmp_path / "rec")
    session.close()
    after = _snapshot(folder)
    after.pop("session.lock")
    assert after == before


def test_cli_serve_on_a_malformed_session_says_one_line(tmp_path):
    folder = tmp_path / "s"
    path = _write(folder, HEADER, "{oops")
    before = _snapshot(folder)
    proc = subprocess.run(
        [sys.executable, "-m", "dfa_viz.cli", "serve", "--session", str(folder), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=600,  # a ceiling for a hung command
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"dfa: error: {path}:2: not a JSON line (Expecting property name enclosed in double quotes)"
    ]
    assert "Traceback" not in proc.stderr + proc.stdout
    assert _snapshot(folder) == before


@pytest.mark.parametrize(
    ("lines", "line", "error"),
    [
        ([HEADER, "[" * 200_000], 2, "not a JSON line (nested too deeply)"),
        (
            [HEADER, TASK.replace('"task_seed": 3', '"task_seed": -1')],
            2,
            f"task.task_seed must be an integer from 0 to {MAX_SEED}, not -1",
        ),
        (
            [HEADER, TASK.replace('"seed": 0', '"seed": -1')],
            2,
            f"task.seed must be an integer from 0 to {MAX_SEED}, not -1",
        ),
        (
            [HEADER.replace("nav2d", "mars"), TASK],
            1,
            f"session.world: unknown world 'mars'; accepted: {', '.join(world_names())}, "
            "module:Class",
        ),
    ],
    ids=["deep", "task_seed", "seed", "world"],
)
def test_cli_serve_refuses_a_bad_session_before_serving(tmp_path, lines, line, error):
    folder = tmp_path / "s"
    path = _write(folder, *lines)
    before = _snapshot(folder)
    proc = subprocess.run(
        [sys.executable, "-m", "dfa_viz.cli", "serve", "--session", str(folder), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=600,  # a ceiling for a hung command
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"dfa: error: {path}:{line}: {error}"]
    assert "Traceback" not in proc.stderr + proc.stdout
    assert "the page is at" not in proc.stdout  # no server was started
    assert _snapshot(folder) == before
