"""Ways of searching a sweep's edit space for failure modes, each replayed on an OutcomeTable
(search.sweep.table): a search asks for one trial (an edit on a task at a place: one rollout)
at a time and sees only the outcomes of the trials it asked for.

exhaustive  the sweep in its own order: task by task, every edit of each
uniform     uniform random sampling of the (edit, task, place) trials, without replacement
surrogate   FATE's manner: a random forest over trial features (slot, concept, value, the task,
            whether the edit adds the object, the place) refitted as outcomes come in; the next
            trials those with the highest predicted failure plus an exploration term (the
            spread of the trees' predictions)
reinforce   RoboMD's manner: a softmax policy over edits, trained by REINFORCE with a running
            baseline; its action is an edit (then one of its untried trials), its reward the
            failure (1 where the policy fails and its task unedited does not)
prior       the learned prior's order (search.prior): each trial's edit scored before any
            rollout, its changes' -log p summed (the rollout features at their training mean)

The two adaptive searches (surrogate, reinforce) drop an edit once its trials confirm it as a
failure mode (the sweep's own interval test): the search is for distinct modes, and a mode
confirmed needs no more rollouts. The fixed orders (exhaustive, uniform, prior) ask every trial
in their order. Every search asks every trial it has not dropped, so each confirms every mode.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from search.prior import GENERIC, LearnedPrior
from search.sweep.cells import cell_edit
from search.sweep.table import OutcomeTable, arm_trials
from sim.core import PRESENCE, Scene, World

Strategy = Callable[[OutcomeTable, int], list[int]]  # (table, seed) -> trials in asked order


class Oracle:
    """The table as a search sees it: a trial's outcome once asked for, and whether the
    trials asked of an edit confirm it."""

    def __init__(self, table: OutcomeTable) -> None:
        self._table = table
        self.asked: list[int] = []
        self._done = np.zeros(len(table.trials), bool)
        self._by_arm: list[list[int]] = [[] for _ in table.arms]

    def ask(self, i: int) -> bool:
        """Roll out trial i: True where it fails and its task unedited does not."""
        assert not self._done[i], f"trial {i} asked twice"
        self._done[i] = True
        self.asked.append(i)
        self._by_arm[self._table.trials[i].arm].append(i)
        return self._table.hit(i)

    def confirmed(self, arm: int) -> bool:
        return self._table.confirms(self._by_arm[arm])

    def done(self, i: int) -> bool:
        return bool(self._done[i])


def exhaustive(table: OutcomeTable, seed: int = 0) -> list[int]:
    return list(range(len(table.trials)))


def uniform(table: OutcomeTable, seed: int = 0) -> list[int]:
    return [int(i) for i in np.random.default_rng(seed).permutation(len(table.trials))]


def features(table: OutcomeTable) -> np.ndarray:
    """float32 (N, F) one-hot trial features: slot, concept, value, task; adds; place > 0."""
    cols: dict[tuple[str, str], int] = {}
    rows = []
    for t in table.trials:
        slot, concept, value = table.arms[t.arm]
        names = [("slot", slot), ("concept", concept), ("value", value), ("task", str(t.task))]
        rows.append([cols.setdefault(n, len(cols)) for n in names])
    x = np.zeros((len(table.trials), len(cols) + 2), np.float32)
    for i, (row, t) in enumerate(zip(rows, table.trials, strict=True)):
        x[i, row] = 1.0
        x[i, -2:] = (t.adds, t.place > 0)
    return x


def surrogate(
    table: OutcomeTable,
    seed: int = 0,
    *,
    start: int = 10,
    grow: float = 0.1,
    explore: float = 1.0,
    trees: int = 25,
) -> list[int]:
    """FATE-style: `start` uniform trials, then in batches (each a `grow` share of the trials
    asked so far, at least one) the untried trials of undropped edits with the highest
    predicted failure + explore x the trees' standard deviation, the forest refitted before
    each batch (seeded: the same seed, the same order)."""
    from sklearn.ensemble import RandomForestClassifier

    rng = np.random.default_rng(seed)
    oracle = Oracle(table)
    x = features(table)
    y = np.zeros(len(table.trials), bool)
    dropped: set[int] = set()
    jitter = rng.random(len(table.trials)) * 1e-6  # ties broken at random, seeded

    def ask(i: int) -> None:
        y[i] = oracle.ask(i)
        arm = table.trials[i].arm
        if arm not in dropped and oracle.confirmed(arm):
            dropped.add(arm)

    for i in rng.permutation(len(table.trials))[: min(start, len(table.trials))]:
        ask(int(i))
    while True:
        open_ = [
            i for i, t in enumerate(table.trials) if not oracle.done(i) and t.arm not in dropped
        ]
        if not open_:
            return oracle.asked
        asked = oracle.asked
        score = np.zeros(len(open_))
        if y[asked].any() and not y[asked].all():
            forest = RandomForestClassifier(
                n_estimators=trees, random_state=int(rng.integers(2**31)), n_jobs=1
            ).fit(x[asked], y[asked])
            per_tree = np.stack(
                [tree.predict_proba(x[open_])[:, 1] for tree in forest.estimators_]
            )  # (trees, M)
            score = per_tree.mean(0) + explore * per_tree.std(0)
        else:
            score += float(y[asked].mean())
        batch = max(1, math.ceil(grow * len(asked)))
        for j in np.argsort(-(score + jitter[open_]), kind="stable")[:batch]:
            i = open_[int(j)]
            if table.trials[i].arm not in dropped:
                ask(i)


def reinforce(
    table: OutcomeTable, seed: int = 0, *, lr: float = 0.5, baseline_rate: float = 0.1
) -> list[int]:
    """RoboMD-style: a softmax over the edits still open (untried trials left, not dropped),
    logits from zero; each step samples an edit, asks one of its untried trials at random,
    and moves the logits by lr x (reward - baseline) x the gradient of log pi (seeded)."""
    rng = np.random.default_rng(seed)
    oracle = Oracle(table)
    left = [list(rng.permutation(ts)) for ts in arm_trials(table)]
    logits = np.zeros(len(table.arms))
    baseline = 0.0
    dropped: set[int] = set()
    while True:
        open_ = np.array([a for a in range(len(left)) if left[a] and a not in dropped], int)
        if not len(open_):
            return oracle.asked
        z = logits[open_] - logits[open_].max()
        pi = np.exp(z) / np.exp(z).sum()  # (A,)
        k = int(rng.choice(len(open_), p=pi))
        arm = int(open_[k])
        reward = float(oracle.ask(int(left[arm].pop())))
        grad = -pi
        grad[k] += 1.0
        logits[open_] += lr * (reward - baseline) * grad
        baseline += baseline_rate * (reward - baseline)
        if oracle.confirmed(arm):
            dropped.add(arm)


def prior_scores(
    prior: LearnedPrior, world: World, scenes: Sequence[Scene], table: OutcomeTable
) -> np.ndarray:
    """float64 (N,): each trial's edit's cost under the prior, -log p summed over its changes,
    from what it knows before a rollout (how common the old and new values are, presence,
    the slot and concept); its rollout features sit at their training mean."""
    column = {k: i for i, k in enumerate(prior.vocabulary)}
    w = np.array(prior.weights)
    n = len(GENERIC)
    cost = np.zeros(len(table.trials))
    for i, t in enumerate(table.trials):
        edit = cell_edit(scenes[t.task], table.arms[t.arm])
        assert edit is not None
        for c in edit.ordered:
            raw = [
                prior.mean[0],
                prior.mean[1],
                prior.looks.log_share(world.space, c.slot, c.concept, c.old),
                prior.looks.log_share(world.space, c.slot, c.concept, c.new),
                1.0 if c.concept == PRESENCE else 0.0,
            ]
            z = float((np.array(raw) - prior.mean) / np.array(prior.scale) @ w[:n]) + prior.bias
            j = column.get((c.slot, c.concept))
            z += w[n + j] if j is not None else 0.0
            cost[i] += float(np.logaddexp(0.0, -z))
    return cost


def prior_order(costs: np.ndarray) -> Strategy:
    """The trials by the prior's cost, lowest first (ties in the sweep's order)."""

    def order(table: OutcomeTable, seed: int = 0) -> list[int]:
        return [int(i) for i in np.argsort(costs, kind="stable")]

    return order


STOCHASTIC = ("uniform", "surrogate", "reinforce")
STRATEGIES: dict[str, Strategy] = {
    "exhaustive": exhaustive,
    "uniform": uniform,
    "surrogate": surrogate,
    "reinforce": reinforce,
}

__all__ = [
    "STOCHASTIC",
    "STRATEGIES",
    "Oracle",
    "Strategy",
    "exhaustive",
    "features",
    "prior_order",
    "prior_scores",
    "reinforce",
    "surrogate",
    "uniform",
]
