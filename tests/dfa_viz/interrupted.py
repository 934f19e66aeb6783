"""What the tests of interrupted writes share: the commands they interrupt, the real `dfa` in a
child that can be killed at a chosen write, and readers that compare what was left.

Killed: the real command is killed with SIGKILL at a chosen real write (an audit hook in the
child sends the signal when the file is opened for writing, so the point is the same on any
machine), then run again (test_killed_writes.py). A full disk: a small tmpfs or a file size
limit (test_full_disk.py). Lines appended to results CSVs and to a session log, cut at an exact
byte (test_cut_lines.py). The commands run uninterrupted once per test session are the
`reference` fixture (conftest.py).
"""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import rerun as rr

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
