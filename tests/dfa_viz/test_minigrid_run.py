"""`dfa run` on MiniGrid and BabyAI worlds as a person runs it: the whole loop on BabyAI levels,
progress shown in every phase, a prompt exit after the report, and memory bounded before it is
spent. Base policies are cloned on first use and kept in the usual cache."""

from __future__ import annotations

import fcntl
import json
import os
import pty
import struct
import subprocess
import sys
import termios
import threading
import time

import pytest

DFA = [sys.executable, "-m", "dfa_viz.cli"]
TINY = ["--budget", "2", "--steps", "10", "--n-eval", "2", "--max-size", "1"]
EXIT_GRACE_S = 120  # a process still alive this long after its report has hung


class Terminal:
    """A pseudo-terminal for a child's stderr, as a person's shell gives it (dfa shows its
    phases and bars only there); what the child wrote is `text` once it has exited."""

    def __init__(self, rows: int = 40, columns: int = 200) -> None:
        self.master, self.slave = pty.openpty()
        size = struct.pack("HHHH", rows, columns, 0, 0)  # a window's size, as a terminal has
        fcntl.ioctl(self.slave, termios.TIOCSWINSZ, size)
        self.chunks: list[bytes] = []
        self.reader = threading.Thread(target=self._drain, daemon=True)

    def _drain(self) -> None:
        while True:
            try:
                data = os.read(self.master, 1 << 16)
            except OSError:  # EIO: every writer has closed it
                return
            if not data:
                return
            self.chunks.append(data)

    def started(self) -> None:
        """Called once the child holds the terminal: the parent's end of it is closed."""
        os.close(self.slave)
        self.reader.start()

    @property
    def text(self) -> str:
        self.reader.join()
        os.close(self.master)
        return b"".join(self.chunks).decode(errors="replace")


def untrained(env_id: str, folder) -> str:
    """A checkpoint of the project's CNN, seeded and never trained, for `env_id`'s frames: a
    policy that fails its tasks whatever processor trained nothing."""
    import torch

    from policy import ImagePolicy, Policy, PolicyConfig, save_policy
    from sim import get_world

    world = get_world(f"minigrid:{env_id}")
    torch.manual_seed(0)
    config = PolicyConfig(world.name, world.obs_shape, world.action_dim, world.discrete)
    save_policy(Policy(ImagePolicy(config)), folder)
    return str(folder)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ["BabyAI-GoToObjS4-v0", "BabyAI-GoToRedBallNoDists-v0"])
def test_babyai_levels_run_end_to_end(env_id, tmp_path):
    policy = untrained(env_id, tmp_path / "policy")
    out = subprocess.run(
        [*DFA, "run", "--world", f"minigrid:{env_id}", "--shift", "other", "--json", *TINY,
         "--policy", policy, "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=1800,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    record = json.loads(out.stdout)  # stdout holds the answer alone (BabyAI's prints go aside)
    assert record["world"] == f"minigrid:{env_id}" and record["failed"] is True
    assert record["instruction"].startswith("go to the ")
    assert record["instruction"].endswith("(from wherever it starts)")
    assert record["budget"] == 2 and record["success_before"] is not None
    assert os.path.isfile(record["recording"])


@pytest.mark.slow
def test_run_shows_every_phase_and_exits_after_its_report(tmp_path):
    """The report's last line, then the process ends: nothing keeps it alive; on stderr, a
    status line names each phase as it starts, and the policy as the user gave it."""
    policy = untrained("BabyAI-GoToObjS4-v0", tmp_path / "policy")
    args = [*DFA, "run", "--world", "minigrid:BabyAI-GoToObjS4-v0", "--shift", "other", *TINY]
    terminal = Terminal()
    proc = subprocess.Popen(
        [*args, "--policy", policy, "--out", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=terminal.slave,
        text=True,
    )
    terminal.started()
    with proc.stdout:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.strip().startswith("recording:"):
                break
        assert lines and lines[-1].strip().startswith("recording:"), lines
        reported = time.monotonic()
        assert proc.wait(timeout=EXIT_GRACE_S) == 0
    assert time.monotonic() - reported < EXIT_GRACE_S
    err = terminal.text
    for phase in (
        f"loading the policy {policy}",
        f"drawing other tasks until the policy {policy} fails one (at most 50)",
        "the demonstration, then the search",
        f"feedback taken; variants of the demonstration, then finetuning the policy {policy}",
        "scoring both policies on 4 fresh tasks",
        "writing the recording",
    ):
        assert f"dfa: {phase}" in err, phase
    assert "base policy" not in err and "base policy" not in "".join(lines)


@pytest.mark.slow
def test_the_base_policy_is_cloned_in_view_and_draws_are_limited(tmp_path):
    """On first use the base policy is cloned with a phase line; tasks are drawn until it
    fails one, at most 50: a report, or one line saying it solved all 50."""
    terminal = Terminal()
    proc = subprocess.Popen(
        [*DFA, "run", "--world", "minigrid:BabyAI-GoToObjS4-v0", "--shift", "other", *TINY,
         "--out", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=terminal.slave,
        text=True,
    )  # fmt: skip
    terminal.started()
    stdout, _ = proc.communicate(timeout=1800)
    err = terminal.text
    assert "dfa: the base policy of minigrid:BabyAI-GoToObjS4-v0" in err
    assert "dfa: drawing other tasks until the base policy fails one (at most 50)" in err
    if proc.returncode == 2:
        last = err.strip().splitlines()[-1]
        assert last.startswith("dfa: error: the base policy solved all 50 "), last
        assert last.endswith("nothing to diagnose; try another seed or shift")
    else:
        assert proc.returncode == 0, err[-2000:]
        assert stdout.strip().splitlines()[-1].strip().startswith("recording:")


LIMITED = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))
from dfa_viz.cli import main
code = main(sys.argv[1:])
peak_kb = int(open("/proc/self/status").read().split("VmHWM:")[1].split()[0])
print("peak", peak_kb * 1024)
sys.exit(code)
"""


def _limited(args: list[str], limit_bytes: int) -> tuple[int, str, int]:
    """Run `dfa ARGS` with its address space limited: (exit code, stderr, peak resident bytes).
    The peak is the child's own high-water mark since its exec (VmHWM), not ru_maxrss, which
    keeps the resident size of the test process it was forked from."""
    env = {**os.environ, "MALLOC_ARENA_MAX": "2"}  # glibc's arenas reserve address space
    out = subprocess.run(
        [sys.executable, "-c", LIMITED.format(limit=limit_bytes), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    return out.returncode, out.stderr, int(out.stdout.split("peak")[1])


def test_frames_too_large_are_one_line_before_memory_is_spent(tmp_path):
    """1600x1600 frames (MultiRoom-N6 at tile 64) once took 8.5 GB and a MemoryError: now one
    line naming a tile that fits, exit 2, under a 3 GiB address-space limit, the peak that of
    the program's own imports."""
    code, err, peak = _limited(
        [
            "run",
            "--world",
            "minigrid:MiniGrid-MultiRoom-N6-v0:tile=64",
            "--out",
            str(tmp_path),
        ],
        3 * 2**30,
    )
    assert code == 2, err[-2000:]
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "give tile=10 or less" in lines[0], err
    assert peak < 1 * 2**30, peak
