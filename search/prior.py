"""A prior over counterfactuals learned from past searches: which single changes of a new task
are likely to belong to a valid minimal edit.

`LearnedPrior` is an L2-regularised logistic regression over features any world has: from the
search's own size-1 pass, each change's first-step distance and the steps it followed the
demonstration, both relative to the unedited scene's; how common the current and the new value
of the (slot, concept) were in training scenes; presence or looks; and which (slot, concept) it
is (one-hot over those seen when fitting). Its labels are past searches' answers: a change is
positive when it belongs to one of the valid minimal edits. The search reads it as costs,
-log p per change, summed over an edit's changes; it only orders the edits, never drops one.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from policy.model import Policy
from search.lockstep import Candidate, rollout_lockstep
from sim.core import (
    ABSENT,
    EMPTY,
    PRESENCE,
    PRESENT,
    Change,
    ConceptSpace,
    Edit,
    Scene,
    Task,
    UserError,
    World,
    files,
)

GENERIC = ("first_step", "followed", "old_common", "new_common", "presence")
"""The world-generic features, in column order; the (slot, concept) one-hot follows them."""
FORMAT = "dfa-learned-prior/1"


@dataclass(frozen=True)
class SearchLog:
    """One past search, as the prior learns from it.

    unedited: the policy's rollout from the unedited scene against the same demonstration.
    singles: every size-1 candidate the search tried.
    answer: the valid edits of the smallest size (empty when there were none).
    """

    scene: Scene
    unedited: Candidate
    singles: tuple[Candidate, ...]
    answer: tuple[Edit, ...]

    @property
    def positives(self) -> frozenset[Change]:
        return frozenset(c for e in self.answer for c in e.changes)


def unedited_candidate(
    world: World,
    policy: Policy,
    scene: Scene,
    demo,
    *,
    epsilon: float | None = None,
    task: Task | None = None,
) -> Candidate:
    """The unedited scene rolled out like a candidate (the baseline the features compare to)."""
    eps = world.epsilon if epsilon is None else epsilon
    return rollout_lockstep(world, policy, scene, demo, [EMPTY], epsilon=eps, task=task)[0]


def search_log(world: World, policy: Policy, scene: Scene, demo, result) -> SearchLog:
    """A SearchLog of a finished `counterfactual_search` (its size-1 pass and its answer)."""
    singles = tuple(c for c in result.tried if c.edit.size == 1)
    answer = tuple(c.edit for c in result.counterfactuals)
    return SearchLog(scene, unedited_candidate(world, policy, scene, demo), singles, answer)


@dataclass(frozen=True)
class Looks:
    """How often each value of each (slot, concept) came up in training scenes.

    counts: ((slot, concept), ((value, count), ...)) sorted; looks are counted over the scenes
        where the object is present, presence ("present"/"absent") over all scenes.
    """

    counts: tuple[tuple[tuple[str, str], tuple[tuple[str, int], ...]], ...]

    @classmethod
    def of(cls, space: ConceptSpace, scenes: Iterable[Scene]) -> Looks:
        tally: dict[tuple[str, str], Counter] = {}
        for scene in scenes:
            for s in space.slots:
                o = scene.obj(s.name)
                if s.optional:
                    tally.setdefault((s.name, PRESENCE), Counter())[
                        PRESENT if o.present else ABSENT
                    ] += 1
                if o.present:
                    for c in s.concepts:
                        tally.setdefault((s.name, c.name), Counter())[o.value(c.name)] += 1
        return cls(tuple((k, tuple(sorted(v.items()))) for k, v in sorted(tally.items())))

    def log_share(self, space: ConceptSpace, slot: str, concept: str, value: str) -> float:
        """log of the value's share, add-one smoothed over the concept's values."""
        n_values = 2 if concept == PRESENCE else len(space.slot(slot).concept(concept).values)
        counts = dict(self.table().get((slot, concept), ()))
        return math.log((counts.get(value, 0) + 1) / (sum(counts.values()) + n_values))

    def table(self) -> dict[tuple[str, str], tuple[tuple[str, int], ...]]:
        return dict(self.counts)


def _followed(c: Candidate) -> int:
    """Steps the candidate matched the demonstration before it was dropped."""
    if c.dropped_at is not None:
        return c.dropped_at
    return int(np.isfinite(c.distances).sum())


def _generic(space: ConceptSpace, looks: Looks, cand: Candidate, unedited: Candidate) -> list:
    (change,) = cand.edit.changes
    horizon = max(len(cand.distances), 1)
    return [
        math.log((float(cand.distances[0]) + 1e-3) / (float(unedited.distances[0]) + 1e-3)),
        (_followed(cand) - _followed(unedited)) / horizon,
        looks.log_share(space, change.slot, change.concept, change.old),
        looks.log_share(space, change.slot, change.concept, change.new),
        1.0 if change.concept == PRESENCE else 0.0,
    ]


@dataclass(frozen=True)
class LearnedPrior:
    """A logistic regression over single changes, fitted on past searches of one world.

    vocabulary: the (slot, concept) pairs of the one-hot columns, as seen when fitting.
    mean, scale: the GENERIC features' standardisation, from the fitting data.
    weights: one per column (GENERIC, then the vocabulary); bias the intercept.
    """

    world: str
    vocabulary: tuple[tuple[str, str], ...]
    looks: Looks
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    weights: tuple[float, ...]
    bias: float
    l2: float

    def features(
        self, space: ConceptSpace, singles: Sequence[Candidate], unedited: Candidate
    ) -> np.ndarray:
        """float64 (N, F) standardised features of the single-change candidates."""
        return _design(space, self.looks, self.vocabulary, singles, unedited, self.mean, self.scale)

    def probabilities(
        self, space: ConceptSpace, singles: Sequence[Candidate], unedited: Candidate
    ) -> np.ndarray:
        """float64 (N,) in (0, 1): each change's chance of belonging to a valid minimal edit."""
        z = self.features(space, singles, unedited) @ np.array(self.weights) + self.bias  # (N,)
        return 1.0 / (1.0 + np.exp(-z))

    def costs(
        self, space: ConceptSpace, singles: Sequence[Candidate], unedited: Candidate
    ) -> dict[Change, float]:
        """-log p per single change: the mapping `search.enumerate.combinations` sums."""
        if not singles:
            return {}
        z = self.features(space, singles, unedited) @ np.array(self.weights) + self.bias  # (N,)
        cost = np.logaddexp(0.0, -z)  # -log sigmoid(z), without overflow
        return {next(iter(c.edit.changes)): float(x) for c, x in zip(singles, cost, strict=True)}

    def check_world(self, world: World) -> None:
        if self.world != world.name:
            raise UserError(f"the learned prior is for world {self.world!r}, not {world.name!r}")

    def to_json(self) -> dict:
        """Plain JSON (numbers, strings, lists); `from_json` reads it back exactly."""
        return {
            "format": FORMAT,
            "world": self.world,
            "features": list(GENERIC),
            "vocabulary": [list(k) for k in self.vocabulary],
            "looks": [[list(k), [list(vc) for vc in v]] for k, v in self.looks.counts],
            "mean": list(self.mean),
            "scale": list(self.scale),
            "weights": list(self.weights),
            "bias": self.bias,
            "l2": self.l2,
        }

    @classmethod
    def from_json(cls, d: Mapping) -> LearnedPrior:
        """Read back `to_json`; a UserError in one line when malformed."""
        try:
            if d["format"] != FORMAT or tuple(d["features"]) != GENERIC:
                raise ValueError(f"format {d['format']!r} with features {d['features']!r}")
            vocabulary = tuple((str(s), str(c)) for s, c in d["vocabulary"])
            looks = Looks(
                tuple(
                    ((str(k[0]), str(k[1])), tuple((str(v), int(n)) for v, n in vals))
                    for k, vals in d["looks"]
                )
            )
            prior = cls(
                str(d["world"]),
                vocabulary,
                looks,
                tuple(float(x) for x in d["mean"]),
                tuple(float(x) for x in d["scale"]),
                tuple(float(x) for x in d["weights"]),
                float(d["bias"]),
                float(d["l2"]),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise UserError(f"malformed learned prior ({type(e).__name__}: {e})") from None
        n = len(GENERIC)
        numbers = (*prior.mean, *prior.scale, *prior.weights, prior.bias)
        if (
            len(prior.mean) != n
            or len(prior.scale) != n
            or len(prior.weights) != n + len(vocabulary)
            or not all(math.isfinite(x) for x in numbers)
            or min(prior.scale) <= 0
        ):
            raise UserError(
                f"malformed learned prior: expected {n} means and scales and "
                f"{n + len(vocabulary)} finite weights"
            )
        return prior

    def save(self, path: Path) -> None:
        files.write_text(Path(path), json.dumps(self.to_json(), indent=1) + "\n")

    @classmethod
    def load(cls, path: Path, world: World | None = None) -> LearnedPrior:
        """Read a prior file (UserError when missing, not JSON, malformed or for another world)."""
        try:
            d = json.loads(Path(path).read_text())
        except FileNotFoundError:
            raise UserError(f"no learned prior at {path}") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise UserError(f"cannot read learned prior {path}: {e}") from None
        except RecursionError:
            raise UserError(f"cannot read learned prior {path}: nested too deeply") from None
        if not isinstance(d, dict):
            raise UserError(f"malformed learned prior {path}: not a JSON object")
        prior = cls.from_json(d)
        if world is not None:
            prior.check_world(world)
        return prior


def _design(
    space: ConceptSpace,
    looks: Looks,
    vocabulary: Sequence[tuple[str, str]],
    singles: Sequence[Candidate],
    unedited: Candidate,
    mean: Sequence[float],
    scale: Sequence[float],
) -> np.ndarray:
    """float64 (N, len(GENERIC) + V): standardised generic features, then the one-hot."""
    column = {k: i for i, k in enumerate(vocabulary)}
    x = np.zeros((len(singles), len(GENERIC) + len(vocabulary)))  # (N, F)
    for i, cand in enumerate(singles):
        (change,) = cand.edit.changes
        x[i, : len(GENERIC)] = _generic(space, looks, cand, unedited)
        j = column.get((change.slot, change.concept))
        if j is not None:
            x[i, len(GENERIC) + j] = 1.0
    x[:, : len(GENERIC)] = (x[:, : len(GENERIC)] - np.array(mean)) / np.array(scale)
    return x


def fit(
    world: World, logs: Sequence[SearchLog], train_scenes: Iterable[Scene], *, l2: float = 1.0
) -> LearnedPrior:
    """Fit the prior on past searches (their size-1 passes and answers) and training scenes.

    Positives and negatives weigh the same in total (a valid edit has 2 of a few hundred
    changes); L2 on every weight but the bias; L-BFGS from zeros, deterministic.
    """
    from scipy.optimize import minimize  # only fitting needs it

    if not any(log.answer for log in logs):
        raise UserError("cannot fit a learned prior: no past search found a counterfactual")
    space = world.space
    looks = Looks.of(space, train_scenes)
    vocabulary = tuple(
        sorted({(c.slot, c.concept) for log in logs for s in log.singles for c in s.edit.changes})
    )
    n = len(GENERIC)
    raw = np.concatenate(
        [
            _design(space, looks, vocabulary, log.singles, log.unedited, [0.0] * n, [1.0] * n)
            for log in logs
        ]
    )  # (N, F)
    y = np.concatenate(
        [[next(iter(s.edit.changes)) in log.positives for s in log.singles] for log in logs]
    ).astype(np.float64)  # (N,) 1 = in a valid minimal edit
    mean = raw[:, :n].mean(axis=0)
    scale = raw[:, :n].std(axis=0)
    scale[scale < 1e-9] = 1.0
    x = raw.copy()
    x[:, :n] = (raw[:, :n] - mean) / scale
    pos = y.sum()
    w_row = np.where(y > 0, 0.5 / pos, 0.5 / (len(y) - pos))  # (N,) balanced, summing to 1
    reg = l2 / len(logs)  # the data term is a mean: more searches, less pull to zero

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w, b = theta[:-1], theta[-1]
        z = x @ w + b  # (N,)
        nll = np.logaddexp(0.0, z) - y * z  # -log-likelihood per row
        p = 1.0 / (1.0 + np.exp(-z))
        g = w_row * (p - y)  # (N,)
        value = float(w_row @ nll + 0.5 * reg * (w @ w))
        grad = np.append(x.T @ g + reg * w, g.sum())
        return value, grad

    theta = minimize(
        loss, np.zeros(x.shape[1] + 1), jac=True, method="L-BFGS-B", options={"maxiter": 500}
    ).x
    return LearnedPrior(
        world.name,
        vocabulary,
        looks,
        tuple(float(v) for v in mean),
        tuple(float(v) for v in scale),
        tuple(float(v) for v in theta[:-1]),
        float(theta[-1]),
        l2,
    )


__all__ = ["GENERIC", "LearnedPrior", "Looks", "SearchLog", "fit", "search_log"]
