"""`dfa sweep` when one machine is not enough: its append-only results file, a sweep killed
part way and resumed giving the files of one never stopped, bad files refused in one line, and
the same sweep on a two-node Ray cluster (started and stopped here) giving the same files."""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
import pytest

from dfa_viz.cli import main

pytestmark = pytest.mark.slow

ARGS = ["--world", "doorkey", "--tasks", "10", "--sizes", "1", "2", "--no-progress"]
UNITS = 5  # 3 units of single edits, 2 of pairs (checked by the whole run)
RAY = str(Path(sys.executable).with_name("ray"))


def _sweep(out: Path, *extra: str, env: dict | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "dfa_viz.cli", "sweep", *ARGS, "--out", str(out), *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=env)


def _units(path: Path) -> dict[tuple[str, int], dict]:
    lines = path.read_text().splitlines()[1:]
    return {(r["what"], r["unit"]): r for r in map(json.loads, lines)}


def _same_files(a: Path, b: Path) -> None:
    for name in ("sweep.csv", "heatmap.png"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert _units(a / "results.jsonl") == _units(b / "results.jsonl")


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> Path:
    """The sweep run once, never stopped."""
    out = tmp_path_factory.mktemp("whole")
    proc = _sweep(out)
    assert proc.returncode == 0, proc.stderr
    units = _units(out / "results.jsonl")
    assert len(units) == UNITS and {w for w, _ in units} == {"singles", "pairs"}
    return out


def test_a_killed_sweep_resumes_to_the_same_files(whole, tmp_path):
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "dfa_viz.cli", "sweep", *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    results = out / "results.jsonl"
    try:
        deadline = time.monotonic() + 1800
        while time.monotonic() < deadline and proc.poll() is None:
            if results.exists() and results.read_bytes().count(b"\n") >= 2:  # header + a unit
                break
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL  # killed, not finished
    kept = results.read_text().splitlines()
    assert 2 <= len(kept) < 1 + UNITS and not (out / "sweep.csv").exists()
    with results.open("a") as f:  # what a kill in the middle of a line leaves
        f.write(kept[-1][: len(kept[-1]) // 2])

    proc = _sweep(out, "--resume")
    assert proc.returncode == 0, proc.stderr
    notes = [line for line in proc.stderr.splitlines() if line.startswith("dfa: note:")]
    assert len(notes) == 1 and "cut short" in notes[0]
    _same_files(out, whole)
    assert results.read_text().splitlines()[: len(kept)] == kept  # kept, not run again


@pytest.mark.parametrize("bad", ["another sweep", "garbled line", "no file"])
def test_a_bad_results_file_is_one_line_and_left_as_it_is(bad, whole, tmp_path, capsys):
    out = tmp_path / "bad"
    out.mkdir()
    results = out / "results.jsonl"
    args = ["sweep", *ARGS, "--out", str(out), "--resume"]
    if bad != "no file":
        lines = (whole / "results.jsonl").read_text().splitlines(keepends=True)
        if bad == "garbled line":
            lines[2] = lines[2][:100] + "\n"
        results.write_text("".join(lines))
        if bad == "another sweep":
            args[args.index("10")] = "9"
    before = results.read_bytes() if results.exists() else None
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dfa: error: --resume:"), err
    expected = {"another sweep": "tasks 10 (now 9)", "garbled line": "line 3", "no file": "no"}
    assert expected[bad] in err[0]
    assert (results.read_bytes() if results.exists() else None) == before
    assert sorted(p.name for p in out.iterdir()) == (["results.jsonl"] if before else [])


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(temp: str) -> None:
    """End the processes of this cluster only: those whose command line names its folder,
    and their children (Ray's workers)."""
    mine = [
        p for p in psutil.process_iter(["cmdline"]) if temp in " ".join(p.info["cmdline"] or ())
    ]
    procs = {p.pid: p for p in mine}
    for p in mine:
        with contextlib.suppress(psutil.NoSuchProcess):
            procs.update({c.pid: c for c in p.children(recursive=True)})
    for p in procs.values():
        with contextlib.suppress(psutil.NoSuchProcess):
            p.terminate()
    _, alive = psutil.wait_procs(list(procs.values()), timeout=2)
    for p in alive:
        with contextlib.suppress(psutil.NoSuchProcess):
            p.kill()


@pytest.fixture
def cluster():
    """A head node bound to 127.0.0.1 and a worker node, one CPU each, token-authenticated;
    yields (address, environment) and stops both, whatever happens."""
    temp = tempfile.mkdtemp(prefix="dfa-ray-", dir="/tmp")  # short: Ray's socket paths
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    env.pop("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", None)
    port = _free_port()
    common = ["--num-cpus", "1", "--disable-usage-stats"]
    try:
        head = [RAY, "start", "--head", "--port", str(port), "--temp-dir", temp]
        head += ["--include-dashboard", "false", *common]
        # Ray's own switch keeps the head on 127.0.0.1 (backends.RAY_LOOPBACK); a worker node
        # with it is refused, and joins by 127.0.0.1's IPv4-mapped IPv6 form instead, which
        # Ray does not swap for the machine's routable address.
        loop = {**env, "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}
        subprocess.run(head, env=loop, check=True, timeout=600, stdout=subprocess.DEVNULL)
        worker = [RAY, "start", "--address", f"[::ffff:127.0.0.1]:{port}", "--temp-dir", temp]
        worker += common
        subprocess.run(worker, env=env, check=True, timeout=600, stdout=subprocess.DEVNULL)
        yield f"127.0.0.1:{port}", env
    finally:
        _stop(temp)
        shutil.rmtree(temp, ignore_errors=True)


def test_a_two_node_ray_cluster_gives_the_same_files(whole, cluster, tmp_path):
    address, env = cluster
    out = tmp_path / "ray"
    proc = _sweep(out, "--backend", "ray", "--address", address, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    _same_files(out, whole)
    probe = "import ray, sys; ray.init(sys.argv[1]); print(sum(n['Alive'] for n in ray.nodes()))"
    nodes = subprocess.run(
        [sys.executable, "-c", probe, address],
        env={**env, "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert nodes.stdout.strip() == "2", nodes.stderr[-2000:]


def test_the_bench_reports_rollouts_per_second_per_core_against_a_baseline():
    """One process against its forward-pass bound's rate, the others against one process's."""
    from dfa_viz.bench.sweep import SWEPT, per_core_rows

    assert {run for run in SWEPT["tabletop"][2]} == {("local", 1), ("local", 2), ("ray", 2)}
    runs = [
        {"backend": "local", "workers": 1, "per_core_s": 100.0, "bound_per_core_s": 400.0},
        {"backend": "local", "workers": 2, "per_core_s": 90.0},
        {"backend": "ray", "workers": 2, "per_core_s": 80.0},
    ]
    rows = per_core_rows("tabletop", runs)
    assert [r[1] for r in rows] == ["0.250x", "0.90x", "0.80x"]
    assert "in one process" in rows[0][0] and "400/s" in rows[0][0]
    assert "2 worker processes" in rows[1][0] and "on Ray" in rows[2][0]
