"""Lines appended to results CSVs and to a session log, cut at an exact byte by a file size
limit: the line that did not fit is never read back as a row, and the files stay whole."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from interrupted import whole_csv

pytestmark = pytest.mark.slow


# in a child: ROOM more bytes may be written to FILE (a file size limit), then CALL runs
CUT = r"""
import json, os, resource, signal, sys

signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


def room(path, more):
    limit = os.path.getsize(path) + more
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))


def unlimited():
    resource.setrlimit(resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))


def attempt(call):
    try:
        call()
    except OSError as e:
        return {"errno": e.errno, "filename": e.filename}
    return None

"""


def run_cut(body: str, *args: str) -> dict:
    proc = subprocess.run(
        [sys.executable, "-c", CUT + body, *args], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_results_rows_that_do_not_fit_are_cut_off_and_never_read(tmp_path, reference):
    ref = reference("q2")
    out = tmp_path / "q2"
    out.mkdir()
    (out / "config.json").write_bytes((ref / "config.json").read_bytes())
    body = r"""
import csv
from dfa_viz.experiment.results import results_folder
from dfa_viz.experiment.runner import Settings
from dfa_viz.configs import Finetuning

out, ref = sys.argv[1], sys.argv[2]
config = json.load(open(os.path.join(ref, "config.json")))["settings"]
settings = Settings(finetuning=Finetuning(**config["finetuning"]), max_size=config["max_size"])
rows = list(csv.DictReader(open(os.path.join(ref, "runs.csv"))))
times = {"duration_s": "1.0", "cpu_s": "1.0", "host": "here"}
folder = results_folder(out, settings)
first, second = [{**rows[0], **times}], [{**rows[1], **times}]
folder.append(first, first)
got = {}
for more in (10, 0):  # part of the timing line fits (it goes first); then none of it
    room(folder.timings_csv, more)
    got[f"timings {more}"] = attempt(lambda: folder.append(second, second))
unlimited()
room(folder.rows_csv, 10)  # the timing fits (its lines are shorter), part of the row
got["runs"] = attempt(lambda: folder.append(second, second))
unlimited()
got["done"] = sorted(map(list, folder.done()))
print(json.dumps(got))
"""
    got = run_cut(body, str(out), str(ref))
    runs, timings = out / "runs.csv", out / "timings.csv"
    efbig = 27
    assert got["timings 10"] == {"errno": efbig, "filename": str(timings)}
    assert got["timings 0"] == {"errno": efbig, "filename": str(timings)}
    assert got["runs"] == {"errno": efbig, "filename": str(runs)}
    first = whole_csv(ref / "runs.csv")[0]
    assert whole_csv(runs) == [first]  # the row that did not fit is not there in part
    assert len(whole_csv(timings)) == 2  # its timing went first; the run runs again
    assert got["done"] == [[first["world"], first["shift"], first["condition"], 2, 0]]


def test_a_line_cut_short_is_not_a_row_for_the_readers(tmp_path, reference):
    from dfa_viz.experiment.explain import ExplainSettings
    from dfa_viz.experiment.explain_results import explain_folder
    from dfa_viz.experiment.results import results_folder
    from dfa_viz.experiment.runner import Settings

    ref = reference("q2")
    config = json.loads((ref / "config.json").read_text())["settings"]
    from dfa_viz.configs import Finetuning

    settings = Settings(Finetuning(**config["finetuning"]), config["max_size"])
    folder = results_folder(tmp_path / "q2", settings)
    whole = (ref / "runs.csv").read_text()
    last = whole.rstrip("\n").rsplit("\n", 1)[1]
    # a row cut inside its last field still has every column: only its missing newline tells
    (tmp_path / "q2" / "runs.csv").write_text(whole[: -len(last) - 1] + last[:-1])
    assert len(folder.rows()) == len(whole_csv(ref / "runs.csv")) - 1
    explain = explain_folder(tmp_path / "explain", ExplainSettings(("counterfactual", "random")))
    tasks = (reference("explain") / "tasks.csv").read_text()
    (tmp_path / "explain" / "tasks.csv").write_text(tasks[:-2])
    assert len(explain.rows()) == tasks.count("\n") - 2


def test_a_session_line_cut_by_a_full_disk_is_dropped_and_files_stay_whole(tmp_path):
    """dfa_viz.app.sessions: an event whose line does not fit raises, is cut back to nothing
    and is not read back; a demonstration that does not fit is not there."""
    body = r"""
from dfa_viz.app import events as E
from dfa_viz.app.sessions import Session
from sim import get_world

folder = sys.argv[1]
s = Session.open(folder, world="nav2d")
s.append(E.TaskLoaded("nav2d", "object_ti", 0, 3))
world = get_world("nav2d")
task = world.test_task("object_ti", 0)
demo = world.demonstrate(task)
room(s.path, 10)  # ten bytes of the next line fit
got = {"append": attempt(lambda: s.append(E.Judged(True)))}
room(s.path, 0)
got["save"] = attempt(lambda: s.save_trajectory(demo, "demo"))
unlimited()
got["left"] = sorted(os.listdir(folder))
print(json.dumps(got))
"""
    from dfa_viz.app import events as E
    from dfa_viz.app.sessions import Session, read_events

    folder = tmp_path / "session"
    got = run_cut(body, str(folder))
    efbig = 27
    assert got["append"]["errno"] == efbig
    assert got["save"] == {"errno": efbig, "filename": str(folder / "demo-0002.npz")}
    assert got["left"] == ["session.jsonl", "session.lock"]  # no demonstration, no temporary
    entries, _, notes = read_events(folder)
    assert [type(e) for _, e in entries] == [E.SessionStarted, E.TaskLoaded]
    assert notes == []  # the torn line was cut back at once: nothing to drop on reading
    s = Session.open(folder, world="nav2d")
    try:
        assert s.append(E.Judged(True)) == 3
    finally:
        s.close()
    entries, _, notes = read_events(folder)
    assert [type(e) for _, e in entries] == [E.SessionStarted, E.TaskLoaded, E.Judged]
    assert notes == [] and (folder / "session.jsonl").read_text().endswith("\n")
