"""What `dfa` writes survives a full disk: the output folder is a small tmpfs where this process
may mount one (root), else the command runs under a file size limit (RLIMIT_FSIZE, SIGXFSZ
ignored, so writes past it fail with EFBIG); it fails with one line naming the file, leaves no
file cut short, and run again with room it finishes."""

from __future__ import annotations

import json
import resource
import signal
import subprocess
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from interrupted import (
    Q2,
    RUN,
    SWEEP,
    dfa,
    listing,
    one_line,
    rrd_content,
    same_outputs,
    whole_csv,
    whole_lines,
)

from dfa_viz.sweep.journal import RESULTS

pytestmark = pytest.mark.slow


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
