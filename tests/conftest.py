import os

os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ.get("DFA_TORCH_THREADS"):  # `make test` runs the suite with 1, then 2
    import torch

    torch.set_num_threads(int(os.environ["DFA_TORCH_THREADS"]))

import pytest

from sim import get_world


@pytest.fixture(scope="session")
def nav():
    return get_world("nav2d")


@pytest.fixture(scope="session")
def nav_policy(nav):
    from policy import base_policy

    return base_policy(nav)


def assert_learns(pairs, *, min_after: float, min_gain: float) -> None:
    """Learning asserted the way another processor cannot break: over several tasks, on the
    mean success after finetuning and the mean gain (pairs: (before, after) per task), with
    margins well below what is measured; never on one task's number."""
    before = [b for b, _ in pairs]
    after = [a for _, a in pairs]
    mean_after = sum(after) / len(after)
    gain = mean_after - sum(before) / len(before)
    assert mean_after >= min_after and gain >= min_gain, (pairs, mean_after, gain)


@pytest.fixture(scope="session")
def learns():
    return assert_learns
