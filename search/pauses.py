"""The cyclic garbage collector paused while a search runs.

A search makes and drops tens of thousands of small values (edits, scenes, candidates), freed
by reference counting; the collector, run every few hundred of them, walks every live object
again and again for cycles that are not there: 5-10% of a tabletop search.
"""

from __future__ import annotations

import functools
import gc
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import ParamSpec, TypeVar

_lock = threading.Lock()
_depth = 0  # searches running now (threads, or one inside another)
_was_enabled = False

P = ParamSpec("P")
R = TypeVar("R")


@contextmanager
def collector_paused() -> Iterator[None]:
    """Pause the collector until the last search running leaves; as it was before, after."""
    global _depth, _was_enabled
    with _lock:
        if _depth == 0:
            _was_enabled = gc.isenabled()
            gc.disable()
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _was_enabled:
                gc.enable()


def paused(fn: Callable[P, R]) -> Callable[P, R]:
    """fn run with the collector paused (collector_paused)."""

    @functools.wraps(fn)
    def run(*args: P.args, **kwargs: P.kwargs) -> R:
        with collector_paused():
            return fn(*args, **kwargs)

    return run
