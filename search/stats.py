"""95% intervals (Wilson's for a rate, Newcombe's for the difference of two paired rates,
Student's t and the bootstrap for a mean) and exact tests over independent units (the
signed-rank test, McNemar's test of paired successes, Holm's correction, the units a test
needs)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

Z95 = 1.959963984540054  # the two-sided 95% normal quantile


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson score interval (95%) of k successes in n trials; (nan, nan) when n == 0."""
    if n == 0:
        return (math.nan, math.nan)
    assert 0 <= k <= n, f"{k} of {n}"
    p, z2 = k / n, Z95 * Z95
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = Z95 * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def newcombe_paired(both: int, first: int, second: int, neither: int) -> tuple[float, float]:
    """95% interval of p1 - p2 for paired binary outcomes (Newcombe 1998, Stat Med 17:2635,
    method 10: the Wilson intervals of p1 and p2 squared and added with the correlation of the
    pairs, continuity-corrected phi). both: pairs where both outcomes are 1; first: only the
    first; second: only the second; neither. p1 = (both + first) / n, p2 = (both + second) / n.
    (nan, nan) when there are no pairs."""
    n = both + first + second + neither
    if n == 0:
        return (math.nan, math.nan)
    p1, p2 = (both + first) / n, (both + second) / n
    l1, u1 = wilson(both + first, n)
    l2, u2 = wilson(both + second, n)
    margins = (both + first) * (second + neither) * (both + second) * (first + neither)
    phi = 0.0
    if margins:
        cross = both * neither - first * second
        corrected = cross - n / 2 if cross > n / 2 else (cross if cross < 0 else 0.0)
        phi = corrected / math.sqrt(margins)
    d = p1 - p2
    low = d - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    high = d + math.sqrt(
        max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2)
    )
    return (max(-1.0, low), min(1.0, high))


def t_interval(values: Sequence[float]) -> tuple[float, float, float]:
    """(mean, low, high): the mean of `values` and its 95% Student t interval. With one value
    the interval is that value; with none, all three are nan."""
    n = len(values)
    if n == 0:
        return (math.nan, math.nan, math.nan)
    mean = math.fsum(values) / n
    if n == 1:
        return (mean, mean, mean)
    from scipy.special import stdtrit  # what scipy.stats.t.ppf computes, a fraction of the import

    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1))
    half = float(stdtrit(n - 1, 0.975)) * sd / math.sqrt(n)
    return (mean, mean - half, mean + half)


# -- tests over independent units -----------------------------------------------------------------
@dataclass(frozen=True)
class SignedRank:
    """The exact one-sided Wilcoxon signed-rank test of paired differences (H1: they lean > 0).

    n: the differences that are not zero (zeros are dropped, Wilcoxon's way); positive: how many
    of those are > 0; statistic: the sum of the positive ones' ranks (mid-ranks for ties);
    p: P(statistic >= observed) over all 2^n equally likely signs, the ranks held as observed
    (exact with ties too); 1.0 when n is 0. p_min = 1 / 2^n is the smallest p n differences
    can give."""

    n: int
    positive: int
    statistic: float
    p: float

    @property
    def p_min(self) -> float:
        return 0.5**self.n


def signed_rank_exact(diffs: Sequence[float], *, decimals: int = 9) -> SignedRank:
    """The exact one-sided signed-rank test of `diffs` (rounded to `decimals` first, so that
    differences equal on paper are zeros and ties rather than float noise)."""
    import numpy as np
    from scipy.stats import rankdata

    d = np.round(np.asarray(diffs, dtype=np.float64), decimals)
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return SignedRank(0, 0, 0.0, 1.0)
    twice = np.rint(2 * rankdata(np.abs(d))).astype(np.int64)  # mid-ranks doubled: integers
    observed = int(twice[d > 0].sum())
    ways = np.zeros(int(twice.sum()) + 1, dtype=np.float64)  # ways[t]: sign choices summing to t
    ways[0] = 1.0
    for r in twice:
        shifted = np.zeros_like(ways)
        shifted[r:] = ways[:-r]
        ways = ways + shifted
    p = float(ways[observed:].sum() / ways.sum())
    return SignedRank(n, int((d > 0).sum()), observed / 2, p)


@dataclass(frozen=True)
class PairedChange:
    """The exact one-sided McNemar test of paired successes (H1: `after` solves more).

    units: the units paired; fixed: those failed before and solved after; broken: solved
    before, failed after. Under H0 each of the fixed + broken discordant units goes either way
    with probability 1/2, so p = P(Binomial(fixed + broken, 1/2) >= fixed); 1.0 when no unit
    changed."""

    units: int
    fixed: int
    broken: int
    p: float


def mcnemar_exact(before: Sequence[bool], after: Sequence[bool]) -> PairedChange:
    """The exact one-sided McNemar test of the same units' outcomes before and after."""
    assert len(before) == len(after), f"{len(before)} units before, {len(after)} after"
    fixed = sum(1 for b, a in zip(before, after, strict=True) if a and not b)
    broken = sum(1 for b, a in zip(before, after, strict=True) if b and not a)
    n = fixed + broken
    p = math.fsum(math.comb(n, k) for k in range(fixed, n + 1)) / 2**n
    return PairedChange(len(before), fixed, broken, p)


def holm(ps: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values of `ps`, in their order: the k-th smallest times
    (m - k + 1), never below an earlier one, at most 1."""
    m = len(ps)
    out = [0.0] * m
    running = 0.0
    for k, i in enumerate(sorted(range(m), key=lambda i: ps[i])):
        running = max(running, min(1.0, (m - k) * ps[i]))
        out[i] = running
    return out


def bootstrap_mean(
    values: Sequence[float], *, resamples: int = 10_000, seed: int = 0
) -> tuple[float, float]:
    """95% percentile bootstrap interval of the mean of `values` (the units resampled with
    replacement, `resamples` times, from a numpy Generator seeded with `seed`); with fewer than
    two values, the mean itself (nan with none)."""
    import numpy as np

    v = np.asarray(values, dtype=np.float64)
    if len(v) < 2:
        m = float(v.mean()) if len(v) else math.nan
        return (m, m)
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, len(v), size=(resamples, len(v)))].mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return (float(low), float(high))


def units_for_power(
    diffs: Sequence[float],
    *,
    alpha: float,
    power: float = 0.8,
    min_nonzero: int = 0,
    most: int = 40,
    resamples: int = 1000,
    seed: int = 0,
) -> int | None:
    """The fewest units (at least len(diffs)) for which the exact one-sided signed-rank test
    reaches p <= alpha, on at least `min_nonzero` non-zero differences, in at least `power` of
    `resamples` samples drawn with replacement from the observed `diffs`; None if `most` units
    do not. Resampling the observed units never
    draws a unit unlike them, so this is a lower bound on what a real experiment needs."""
    import numpy as np

    rng = np.random.default_rng(seed)
    d = np.round(np.asarray(diffs, dtype=np.float64), 9)
    if len(d) == 0 or not (d > 0).any():
        return None
    seen: dict[tuple[float, ...], bool] = {}
    for n in range(len(d), most + 1):
        passed = 0
        for row in d[rng.integers(0, len(d), size=(resamples, n))]:
            key = tuple(sorted(row.tolist()))
            if key not in seen:
                test = signed_rank_exact(key)
                seen[key] = test.n >= min_nonzero and test.p <= alpha
            passed += seen[key]
        if passed >= power * resamples:
            return n
    return None
