"""`dfa serve`: one server's memory across many loops of the page, in a process of its own."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from page_wire import PageWire, free_port

# -- memory of one server across many loops -----------------------------------------------------
# `dfa serve`'s own start, in a process of its own; for each line on stdin (the page is idle),
# what is live in it: resident MB after a full collection and malloc_trim (what is live, not
# what malloc keeps cached), and its threads
SERVER_LOOPS = """
import ctypes, gc, json, os, sys
from dfa_viz.app.server import open_state, start
from dfa_viz.configs import AdaptConfig, Finetuning

def live():
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    with open("/proc/self/statm") as f:
        rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    return {"rss": rss, "threads": len(os.listdir("/proc/self/task"))}

# a tiny finetune (one variant, 10 steps) and evaluation: what matters is what a loop leaves
quick = AdaptConfig(budget=2, finetuning=Finetuning(steps=10, steps_per_trajectory=1, n_eval=2))
state = open_state(session=sys.argv[1], out=sys.argv[2], adapt=quick)
app = start(port=int(sys.argv[3]), state=state)
try:
    for _ in sys.stdin:
        print("live:", json.dumps(live()), flush=True)
    print("lists:", json.dumps(bool(state.session.replay())), flush=True)
finally:
    app.stop()
"""
LOOPS = 20


@pytest.mark.slow
@pytest.mark.timeout(3 * 3600)  # a ceiling for a hang: 20 loops took 3 to 7 minutes on 2 cores
def test_one_server_stays_within_bounded_memory_over_many_loops(tmp_path):
    """20 full loops through the page in one server process (a fresh one, as `dfa serve` is):
    a tab (page_wire.PageWire: viser's protocol, as the browser sends it) presses Load task
    (then "Continue: another task"), Failed, "Continue: the expert shows it", TI on every
    edited concept and "Continue: make variants and finetune", which finetunes and evaluates;
    the server draws every step for it. The memory it holds levels off after the first loops.

    Measured on nav2d (live MB after malloc_trim, on 2 busy cores): 396 with the page open,
    548 after the first loop (the policy, its training demonstrations, torch's kernels: what
    the first loops bring in, +166 MB by the median of loops 1-5), then +5 to +8 MB (two runs)
    from the median of loops 6-10 to that of loops 16-20 (bounded caches still filling:
    nav2d's agent discs, an LRU of 4,096, among them), 16 threads throughout. While rerun kept
    every stream, loops added 7-9 MB each. The bound, an eighth of what the first loops brought
    in (21 MB here), fails a leak of 2 MB a loop on top of what was measured.
    """

    from dfa_viz.app.feedback import TI
    from dfa_viz.app.page import ASK_EXPERT, FINETUNE, NEXT_TASK

    ceiling = 1200.0  # a job takes seconds to minutes; this only ends a hang
    printed: list[str] = []
    rss, threads = [], []
    with subprocess.Popen(
        [sys.executable, "-c", SERVER_LOOPS, str(tmp_path / "s"), str(tmp_path), str(free_port())],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl", "PYTHONUNBUFFERED": "1"},
    ) as proc:

        def after(prefix: str) -> str:
            """What the server prints after `prefix` next (its other lines are kept)."""
            while line := proc.stdout.readline():
                printed.append(line)
                if line.startswith(prefix):
                    return line.removeprefix(prefix).strip()
            raise AssertionError("".join(printed)[-3000:])

        def live() -> dict:
            proc.stdin.write("now\n")
            proc.stdin.flush()
            return json.loads(after("live:"))

        try:
            tab = PageWire(after("dfa serve: the page is at "))
            tab.wait_enabled("Load task", ceiling)
            start = live()["rss"]
            for loop in range(LOOPS):
                tab.click("Load task" if loop == 0 else NEXT_TASK)
                tab.click("Failed")
                tab.click(ASK_EXPERT)
                tab.wait(lambda: tab.find(FINETUNE, "Button"), "the feedback", ceiling)
                for uuid in tab.find(TI, "Button"):  # every edited concept, task-irrelevant
                    tab.update(uuid, value=True)
                tab.click(FINETUNE)
                tab.wait(lambda: tab.enabled(NEXT_TASK), "the finetuned policy's scores", ceiling)
                assert "fresh tasks with the shift" in tab.text()
                now = live()
                rss.append(now["rss"])
                threads.append(now["threads"])
            tab.close()
            proc.stdin.close()
            lists = json.loads(after("lists:"))
            assert proc.wait(timeout=ceiling) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
    assert "Traceback" not in "".join(printed), "".join(printed)[-3000:]
    log = (tmp_path / "s" / "session.jsonl").read_text().splitlines()
    kinds = [json.loads(x)["type"] for x in log]
    assert kinds.count("finetune") == LOOPS  # every loop went all the way

    def median(values):
        return sorted(values)[len(values) // 2]

    early = median(rss[0:5]) - start
    late = median(rss[15:20]) - median(rss[5:10])
    report = f"with the page open {start:.0f}; per loop " + ", ".join(f"{r:.0f}" for r in rss)
    print(f"live MB {report}; threads {threads}")  # shown with -s
    assert early > 0, report
    assert late < early / 8, f"live MB {report}"
    # a pool thread started once, late, on a loaded machine is not a leak (seen: 15 -> 16 at
    # loop 9); a thread kept per loop would add 15 from loop 5 to loop 20
    assert threads[-1] <= threads[4] + 2, f"threads per loop: {threads}"
    assert not lists  # the session keeps no events in memory
