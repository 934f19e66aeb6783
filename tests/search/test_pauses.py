"""The garbage collector is paused while a search runs and as it was after."""

import dataclasses
import gc
import threading

from policy import failing_test_task
from search import SearchConfig, counterfactual_search
from search.pauses import collector_paused


def test_a_search_runs_with_the_collector_paused_and_gives_it_back(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "other", 0)
    seen: list[bool] = []
    config = dataclasses.replace(SearchConfig.for_world(nav), joint_below=0)  # size by size
    assert gc.isenabled()
    counterfactual_search(
        nav,
        nav_policy,
        task.scene,
        nav.demonstrate(task),
        config=config,
        on_progress=lambda *_: seen.append(gc.isenabled()),
    )
    assert seen and not any(seen) and gc.isenabled()


def test_pauses_nest_and_overlap_and_keep_a_disabled_collector_disabled():
    with collector_paused():
        with collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert gc.isenabled()
    # two threads: the collector comes back only when the last one leaves
    inside, leave = threading.Event(), threading.Event()

    def other():
        with collector_paused():
            inside.set()
            leave.wait()

    t = threading.Thread(target=other, daemon=True)
    try:
        with collector_paused():
            t.start()
            inside.wait()  # the other thread is inside its pause
        assert not gc.isenabled()
    finally:
        leave.set()
    t.join()
    assert gc.isenabled()
    gc.disable()
    try:
        with collector_paused():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()
