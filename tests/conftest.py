import os

os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ.get("DFA_TORCH_THREADS"):  # `make test` runs the suite with 1, then 2
    import torch

    torch.set_num_threads(int(os.environ["DFA_TORCH_THREADS"]))

from pathlib import Path

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


class StudyCheck:
    """The study's statistics computed again from their definitions (no scipy): the tests of
    `dfa study analyse` compare its numbers with these."""

    @staticmethod
    def correct(truth: dict, selected, none: bool) -> bool:
        """The paper's rule: an object shift's changed concept ticked; for a distractor, any
        concept of the added object (its presence or a look); "none" for an other shift."""
        if truth["kind"] == "other":
            return none
        if truth["kind"] == "distractor":
            added = truth["cause"].partition(".")[0]
            return not none and any(c.partition(".")[0] == added for c in selected)
        return not none and all(c in selected for c in truth["required"])

    @staticmethod
    def chi2(a: int, b: int, c: int, d: int) -> tuple[float, float]:
        """Pearson's chi-squared of [[a, b], [c, d]] (no correction) and its p with 1 df."""
        import math

        n = a + b + c + d
        stat = n * (a * d - b * c) ** 2 / ((a + b) * (c + d) * (a + c) * (b + d))
        return stat, math.erfc(math.sqrt(stat / 2))

    @staticmethod
    def fisher(a: int, b: int, c: int, d: int) -> float:
        """Two-sided Fisher's exact p of [[a, b], [c, d]]: the hypergeometric probability of
        every table with the same margins no likelier than the one seen."""
        from math import comb

        row, col, n = a + b, a + c, a + b + c + d

        def prob(x: int) -> float:
            return comb(col, x) * comb(n - col, row - x) / comb(n, row)

        seen = prob(a)
        tables = range(max(0, row + col - n), min(row, col) + 1)
        return min(1.0, sum(prob(x) for x in tables if prob(x) <= seen * (1 + 1e-7)))

    @staticmethod
    def wilcoxon(x, y) -> float:
        """Two-sided exact signed-rank p: every sign assignment of the ranked differences."""
        import itertools

        d = [a - b for a, b in zip(x, y, strict=True) if a != b]
        order = sorted(range(len(d)), key=lambda i: abs(d[i]))
        ranks = [0.0] * len(d)
        i = 0
        while i < len(d):  # ties share the mean of their ranks
            j = i
            while j + 1 < len(d) and abs(d[order[j + 1]]) == abs(d[order[i]]):
                j += 1
            for k in range(i, j + 1):
                ranks[order[k]] = (i + j) / 2 + 1
            i = j + 1
        observed = sum(r for r, v in zip(ranks, d, strict=True) if v > 0)
        mean = sum(ranks) / 2
        flips = list(itertools.product((0, 1), repeat=len(d)))
        extreme = sum(
            abs(sum(r for r, s in zip(ranks, signs, strict=True) if s) - mean)
            >= abs(observed - mean) - 1e-9
            for signs in flips
        )
        return extreme / len(flips)


@pytest.fixture(scope="session")
def study_check():
    return StudyCheck


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """A small study made by the real command (nav2d: 3 questions, 5 tasks); a module that
    needs another study defines its own `study`."""
    from dfa_viz.cli import main

    root = tmp_path_factory.mktemp("study")
    toml = root / "study.toml"
    toml.write_text('seed = 0\nconditions = ["none", "counterfactual"]\n[tasks]\nnav2d = 1\n')
    out = root / "s"
    args = ["--protocol", str(toml), "--out", str(out), "--participants", "4"]
    assert main(["study", "new", *args]) == 0
    assert (root / "s" / "protocol.toml").read_text() == toml.read_text()
    return root / "s"
