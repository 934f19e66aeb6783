"""Timing helpers of the benchmarks: the best of a few repeats, and the machine's name."""

from __future__ import annotations

import platform
import time
from collections.abc import Callable


def best_of(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def machine() -> str:
    """One line naming the machine the figures came from."""
    import torch

    from policy.base import machine_name

    return (
        f"{machine_name()}; torch {torch.__version__} with {torch.get_num_threads()} threads; "
        f"Python {platform.python_version()}"
    )
