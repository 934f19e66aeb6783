"""What `dfa` writes survives a process killed with SIGKILL at a chosen real write (an audit
hook in the child sends the signal when the file is opened for writing, so the point is the same
on any machine): run again, it resumes or starts afresh and ends with the files an
uninterrupted run writes (the `reference` fixture)."""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
from interrupted import EXPLAIN, PRIOR, SWEEP, dfa, listing, same_outputs, whole_csv, whole_lines

from dfa_viz.sweep.journal import RESULTS
from sim.core import files

pytestmark = pytest.mark.slow


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
