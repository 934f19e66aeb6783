"""What `dfa` writes survives a killed process and a full disk.

Killed: the real command is killed with SIGKILL at a chosen real write (an audit hook in the
child sends the signal when the file is opened for writing, so the point is the same on any
machine), then run again; it resumes or starts afresh, and ends with the files an
uninterrupted run writes. A full disk: the output folder is a small tmpfs where this process
may mount one (root), else the command runs under a file size limit (RLIMIT_FSIZE, SIGXFSZ
ignored, so writes past it fail with EFBIG); it fails with one line naming the file, leaves no
file cut short, and run again with room it finishes. Lines appended to results CSVs and to a
session log are tested under a file size limit, which cuts a write at an exact byte.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import resource
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import rerun as rr

from dfa_viz.sweep.journal import RESULTS
from sim.core import files

pytestmark = pytest.mark.slow

SWEEP = ("sweep", "--world", "nav2d", "--tasks", "5", "--no-progress")
EXPLAIN = (
    *("experiment", "explain", "--world", "nav2d", "--shift", "object_ti", "--tasks", "3"),
    *("--method", "counterfactual", "random", "--workers", "1", "--no-progress"),
)
PRIOR = ("prior", "--world", "nav2d", "--tasks", "3")
Q2 = (
    *("experiment", "q2", "--world", "nav2d", "--shift", "object", "--budgets", "2", "3"),
    *("--seeds", "1", "--conditions", "oracle", "--steps", "20", "--steps-per-trajectory", "1"),
    *("--n-eval", "2", "--workers", "1", "--no-progress"),
)
RUN = (
    *("run", "--world", "nav2d", "--steps", "20", "--steps-per-trajectory", "1"),
    *("--n-eval", "2", "--budget", "2", "--json"),
)

# `dfa ARGS`, killed with SIGKILL when it opens for writing the NTH file whose name matches
# PATTERN (argv: PATTERN NTH ARGS...; an empty PATTERN never kills)
CHILD = r"""
import fnmatch, os, signal, sys

pattern, nth = sys.argv[1], int(sys.argv[2])
opened = 0


def kill_at_open(event, args):
    global opened
    if event != "open" or not pattern or not isinstance(args[0], (str, bytes, os.PathLike)):
        return
    writing = isinstance(args[2], int) and args[2] & (os.O_WRONLY | os.O_RDWR)
    if writing and fnmatch.fnmatch(os.path.basename(os.fsdecode(args[0])), pattern):
        opened += 1
        if opened == nth:
            os.kill(os.getpid(), signal.SIGKILL)


sys.addaudithook(kill_at_open)
from dfa_viz.cli import main

sys.exit(main(sys.argv[3:]))
"""


def dfa(
    *args: str,
    kill_at: tuple[str, int] = ("", 0),
    limit: Callable[[], None] | None = None,
    tag: str = "",
) -> subprocess.CompletedProcess:
    """The real `dfa` command in a child process; `limit` runs in the child before it starts
    (a file size limit); `tag` marks the child and its workers' environment."""
    env = {**os.environ, "INTERRUPTED_WRITES_TAG": tag} if tag else None
    return subprocess.run(
        [sys.executable, "-c", CHILD, kill_at[0], str(kill_at[1]), *args],
        capture_output=True,
        text=True,
        timeout=900,
        preexec_fn=limit,
        env=env,
    )


def listing(folder: Path) -> dict[str, Path]:
    """Every file under `folder`, hidden ones included, by its path relative to it."""
    return {str(p.relative_to(folder)): p for p in sorted(folder.rglob("*")) if p.is_file()}


def rrd_content(path: Path) -> list:
    """What a recording holds, without rerun's row and chunk ids (time-based)."""
    out = []
    for chunk in rr.chunk.RrdReader(path).store().stream():
        columns = chunk.to_record_batch().to_pydict()
        data = sorted((k, repr(v)) for k, v in columns.items() if "RowId" not in k)
        out.append((str(chunk.entity_path), chunk.is_static, data))
    return sorted(out)


def same_outputs(ours: Path, theirs: Path, *, differ: tuple[str, ...] = ()) -> None:
    """The same files, hidden ones included; recordings by what they hold; `differ`: files
    whose bytes change between executions (timings), compared by name only."""
    mine, other = listing(ours), listing(theirs)
    assert sorted(mine) == sorted(other)
    for name, path in mine.items():
        if name.endswith(".rrd"):
            assert rrd_content(path) == rrd_content(other[name]), name
        elif name == "table.md" and "## Time per task" in path.read_text():
            cut = path.read_text().index("## Time per task")  # wall seconds
            assert path.read_text()[:cut] == other[name].read_text()[:cut]
        elif name not in differ:
            assert path.read_bytes() == other[name].read_bytes(), name


def one_line(proc: subprocess.CompletedProcess, path: Path) -> str:
    """A run that ran out of room: exit 1 and one line on stderr naming a file under `path`."""
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(err) == 1, proc.stderr[-3000:]
    assert err[0].startswith(f"dfa: error: {path}") and "no space left" in err[0], err[0]
    return err[0]


def whole_lines(path: Path) -> bool:
    """A JSON-lines file whose every line is whole (ends with a newline and reads back)."""
    text = path.read_text()
    return text.endswith("\n") and all(json.loads(line) for line in text.splitlines())


def whole_csv(path: Path) -> list[dict[str, str]]:
    """A CSV that ends with a whole line, every row with every column."""
    text = path.read_text()
    assert text.endswith("\n"), path
    rows = list(csv.DictReader(io.StringIO(text)))
    assert all(None not in r and None not in r.values() for r in rows), path
    return rows


# -- references: the commands uninterrupted -------------------------------------------------------
@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Callable[[str], Path]:
    """The output folder of each command run once, uninterrupted (made on first use)."""
    made: dict[str, Path] = {}
    commands = {"sweep": SWEEP, "explain": EXPLAIN, "prior": PRIOR, "q2": Q2}

    def get(name: str) -> Path:
        if name not in made:
            out = tmp_path_factory.mktemp(f"reference-{name}")
            target = out / "prior.json" if name == "prior" else out / "out"
            proc = dfa(*commands[name], "--out", str(target))
            assert proc.returncode == 0, proc.stderr[-3000:]
            made[name] = target.parent if name == "prior" else target
        return made[name]

    return get


# -- kill -9 --------------------------------------------------------------------------------------
def test_a_sweep_killed_while_writing_its_files_starts_afresh_to_the_same_files(
    tmp_path, reference
):
    out = tmp_path / "out"
    killed = dfa(*SWEEP, "--out", str(out), kill_at=(".sweep.*.tmp.rrd", 2))
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-3000:]
    left = listing(out)
    # the table and the picture waited for the recording: nothing in place but the results
    # file (append-only, each unit's line whole), only temporaries
    temps = [n for n in left if n != RESULTS]
    assert RESULTS in left and whole_lines(left[RESULTS]), left
    assert len(temps) == 3 and all(n.startswith(".") and ".tmp." in n for n in temps), left
    for name in ("sweep.csv", "heatmap.png", "sweep.rrd"):
        assert len(files.stale_temps(out / name)) == 1, name
    again = dfa(*SWEEP, "--out", str(out))
    assert again.returncode == 0, again.stderr[-3000:]
    same_outputs(out, reference("sweep"))  # the killed run's temporaries gone too


def _tagged(tag: str) -> list[int]:
    """Live processes whose environment carries `tag` (a command and its pool's workers)."""
    pids = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            if "\nState:\tZ" in (proc / "status").read_text():
                continue
            if f"INTERRUPTED_WRITES_TAG={tag}".encode() in (proc / "environ").read_bytes():
                pids.append(int(proc.name))
    return pids


def test_explain_killed_after_its_first_rows_resumes_to_the_same_files(tmp_path, reference):
    out = tmp_path / "out"
    tag = uuid.uuid4().hex
    # killed as it opens tasks.csv for the second task's rows: the first task's are there
    killed = dfa(*EXPLAIN, "--out", str(out), kill_at=("tasks.csv", 2), tag=tag)
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-3000:]
    rows = whole_csv(out / "tasks.csv")
    assert len(rows) == 2 and {r["seed"] for r in rows} == {"0"}
    # the pool's worker ends with the process that started it instead of waiting forever
    deadline = time.monotonic() + 120
    while _tagged(tag) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert not _tagged(tag), "a worker outlived the killed command"
    again = dfa(*EXPLAIN, "--out", str(out))
    assert again.returncode == 0, again.stderr[-3000:]
    assert "3 tasks planned: 1 already in" in again.stdout
    same_outputs(out, reference("explain"), differ=("timings.csv",))
    timings = whole_csv(out / "timings.csv")
    assert len(timings) == len(whole_csv(out / "tasks.csv"))  # one per row, none twice


def test_a_prior_killed_while_writing_starts_afresh_to_the_same_file(tmp_path, reference):
    out = tmp_path / "prior.json"
    killed = dfa(*PRIOR, "--out", str(out), kill_at=(".prior.*.tmp.json", 2))
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-3000:]
    assert not out.exists() and len(files.stale_temps(out)) == 1
    again = dfa(*PRIOR, "--out", str(out))
    assert again.returncode == 0, again.stderr[-3000:]
    same_outputs(tmp_path, reference("prior"))


def test_a_dead_process_temporary_goes_at_the_next_write_a_live_one_stays(tmp_path):
    target = tmp_path / "table.csv"
    code = "import sys; from sim.core import files; print(files.temp_beside(sys.argv[1]))"
    dead = Path(
        subprocess.run(
            [sys.executable, "-c", code, str(target)], capture_output=True, text=True, check=True
        ).stdout.strip()
    )
    other = tmp_path / ".table.1.tmp.csv"  # not a name temp_beside gives
    other.write_text("")
    assert files.stale_temps(target) == [dead]
    live = files.temp_beside(target)  # this process's
    assert not dead.exists() and files.stale_temps(target) == []
    files.write_text(target, "a\n")
    assert live.exists() and other.exists() and target.read_text() == "a\n"


# -- a full disk ----------------------------------------------------------------------------------
@dataclass
class Disk:
    """A folder with little room: a tmpfs of `size` bytes (mounted), or, where this process
    may not mount one, a folder written under a file size limit of `size` bytes."""

    folder: Path
    size: int
    mounted: bool

    def limit(self) -> Callable[[], None] | None:
        """For a child process: nothing on a tmpfs, else the file size limit."""
        if self.mounted:
            return None
        size = self.size

        def preexec() -> None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (size, resource.RLIM_INFINITY))

        return preexec

    def grow(self) -> None:
        """Make room: a bigger tmpfs (the files stay), or no limit."""
        if self.mounted:
            subprocess.run(
                ["mount", "-o", "remount,size=256m", str(self.folder)], check=True, timeout=60
            )
        else:
            self.size = resource.RLIM_INFINITY


@pytest.fixture
def small_disk(tmp_path) -> Iterator[Callable[[int], Disk]]:
    disks: list[Disk] = []

    def make(size_kib: int) -> Disk:
        folder = tmp_path / f"disk{len(disks)}"
        folder.mkdir()
        mount = ["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs", str(folder)]
        try:
            mounted = subprocess.run(mount, capture_output=True, timeout=60).returncode == 0
        except OSError:  # no mount command
            mounted = False
        disks.append(Disk(folder, size_kib * 1024, mounted))
        return disks[-1]

    try:
        yield make
    finally:
        for disk in disks:
            if disk.mounted:
                subprocess.run(["umount", str(disk.folder)], timeout=60)


def test_a_sweep_on_a_full_disk_writes_nothing_then_finishes_with_room(small_disk, reference):
    disk = small_disk(100)  # the table and the picture fit, the recording does not
    out = disk.folder / "out"
    proc = dfa(*SWEEP, "--out", str(out), limit=disk.limit())
    one_line(proc, out / "sweep.rrd")
    left = listing(out)  # no part of a set, no temporary; the units' results, each line whole
    assert list(left) == [RESULTS] and whole_lines(left[RESULTS]), left
    disk.grow()
    again = dfa(*SWEEP, "--out", str(out), limit=disk.limit())
    assert again.returncode == 0, again.stderr[-3000:]
    same_outputs(out, reference("sweep"))


def test_q2_on_a_full_disk_keeps_its_rows_and_resumes_with_room(small_disk, reference):
    disk = small_disk(24)  # the rows fit, the plots do not
    out = disk.folder / "out"
    proc = dfa(*Q2, "--out", str(out), limit=disk.limit())
    one_line(proc, out)
    left = listing(out)
    assert not [n for n in left if Path(n).name.startswith(".")], left  # no temporary
    assert not [n for n in left if n.endswith((".png", ".rrd"))], left
    rows = whole_csv(out / "runs.csv")
    assert rows == whole_csv(reference("q2") / "runs.csv")  # every run, whole
    disk.grow()
    again = dfa(*Q2, "--out", str(out), limit=disk.limit())
    assert again.returncode == 0, again.stderr[-3000:]
    assert "2 runs planned: 2 already in" in again.stdout
    same_outputs(out, reference("q2"), differ=("timings.csv",))


def test_a_run_whose_recording_does_not_fit_leaves_none_then_writes_it(small_disk):
    disk = small_disk(100)
    out = disk.folder / "out"
    recording = out / "nav2d-object_ti-seed0.rrd"
    proc = dfa(*RUN, "--out", str(out), limit=disk.limit())
    one_line(proc, recording)
    assert listing(out) == {}
    disk.grow()
    again = dfa(*RUN, "--out", str(out), limit=disk.limit())
    assert again.returncode == 0, again.stderr[-3000:]
    assert json.loads(again.stdout)["recording"] == str(recording)
    entities = {e for e, _, _ in rrd_content(recording)}
    assert {"/rollouts/failed/frame", "/rollouts/finetuned/frame"} <= entities


# -- lines appended: results CSVs and the session log, cut at an exact byte ----------------------
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
