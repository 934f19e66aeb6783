"""Timing helpers of the benchmarks: the best of a few repeats, and the machine's name."""

from __future__ import annotations

import platform
import time
from collections.abc import Callable

MAX_RUNS = 200  # of a figure timed for at least min_s


def best_of(fn: Callable[[], object], repeats: int, *, min_s: float = 0.0) -> tuple[float, object]:
    """(the best seconds of fn's runs, the last run's output): `repeats` runs, more while they
    have taken under `min_s` in all (up to MAX_RUNS): a search of a few milliseconds timed
    three times is mostly the noise of its first runs."""
    best, out, spent, runs = float("inf"), None, 0.0, 0
    while runs < repeats or (spent < min_s and runs < MAX_RUNS):
        t0 = time.perf_counter()
        out = fn()
        took = time.perf_counter() - t0
        best, spent, runs = min(best, took), spent + took, runs + 1
    return best, out


def machine() -> str:
    """One line naming the machine the figures came from."""
    import torch

    from policy.base import machine_name

    return (
        f"{machine_name()}; torch {torch.__version__} with {torch.get_num_threads()} threads; "
        f"Python {platform.python_version()}"
    )
