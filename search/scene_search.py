"""Failures beyond single concepts: a world's continuous scene parameters (World.scene_parameters,
e.g. where the goal stands) searched for scenes where the policy fails, near training tasks.

A probe is one rollout: a training task with its parameters moved by up to `spread` of each
parameter's range from the task's own values (a point that gives no valid scene, objects
overlapping, is drawn again), judged by the task's R'. It counts as a failure where the policy
fails and the world's expert, where it has one, succeeds from the same scene (checked only
where the policy failed, as the sweep does).

uniform    `budget` probes drawn uniformly (the matched control: the same budget, the same
           neighbourhoods)
surrogate  FATE's manner over parameters: `start` uniform probes, then batches of `batch`, each
           the candidates (of `pool` drawn uniformly) with the highest predicted failure plus
           `explore` x the spread of the trees' predictions, from a random forest over (task,
           parameters, offsets) refitted on every probe so far before each batch

Both roll each batch out in lockstep (search.sweep.rollouts) and are seeded: the same seed, the
same probes. No rerun or viser here; scikit-learn for the forest.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from search.sweep.rollouts import roll
from sim.core import Task, UserError, World
from sim.core.parameters import InvalidScene

Act = Callable[[np.ndarray], np.ndarray]
MAX_DRAWS = 1000  # draws for one valid point before the neighbourhood is called empty
CELLS = 20  # distinct failures: per task, a grid of CELLS bins over each parameter's range


@dataclass(frozen=True)
class SceneSearch:
    """How a parameter search looks."""

    budget: int = 200
    """Probes (rollouts) per search."""
    spread: float = 0.05
    """Each parameter moves up to this share of its range from the task's own value."""
    start: int = 20
    """Uniform probes before the first forest."""
    batch: int = 20
    """Probes per batch (rolled out together; the forest refitted before each)."""
    pool: int = 400
    """Candidates the forest scores for each batch."""
    explore: float = 1.0
    """Weight of the trees' spread beside their mean predicted failure."""
    diverse: float = 0.5
    """Weight of the distance to the nearest probe so far (adaptive random testing: in
    offsets as a share of the neighbourhood, probes of other tasks out of reach)."""
    trees: int = 25

    def check(self) -> None:
        if self.budget < 1:
            raise UserError(f"the budget is probes per search, at least 1, not {self.budget}")
        if not 0 < self.spread <= 1:
            raise UserError(f"the spread is a share of each range, in (0, 1], not {self.spread}")
        if self.batch < 1 or self.start < 1 or self.pool < self.batch:
            raise UserError("start and batch must be at least 1 and the pool at least a batch")


@dataclass(frozen=True)
class Probe:
    """One rollout of the search: task index, parameter values, and its outcome."""

    task: int
    values: tuple[float, ...]
    """The parameters of the scene rolled out (a world that projects them: as projected)."""
    failed: bool
    """The policy failed R' and the expert (where the world has one) did not."""
    expert_failed: bool = False
    """The policy failed but so did the expert: not a failure of the policy."""

    def to_dict(self) -> dict:
        return {
            "task": self.task,
            "values": [round(v, 4) for v in self.values],
            "failed": self.failed,
            "expert_failed": self.expert_failed,
        }


class Neighbourhoods:
    """The training tasks' neighbourhoods in parameter space: where the probes are drawn."""

    def __init__(self, world: World, tasks: Sequence[Task], spread: float) -> None:
        if not world.scene_parameters:
            raise UserError(f"{world.name} declares no continuous scene parameters to search")
        self.world, self.tasks = world, list(tasks)
        params = world.scene_parameters
        self.low = np.array([p.low for p in params], np.float64)  # (P,)
        self.high = np.array([p.high for p in params], np.float64)  # (P,)
        self.base = np.array([world.parameters_of(t.scene) for t in tasks], np.float64)  # (K, P)
        self.reach = spread * (self.high - self.low)  # (P,)

    def draw(self, rng: np.random.Generator, n: int) -> list[tuple[int, tuple[float, ...]]]:
        """n valid (task index, values), each task drawn uniformly, each value uniformly
        within the task's neighbourhood (clipped to the range)."""
        out = []
        for _ in range(n):
            for _ in range(MAX_DRAWS):
                k = int(rng.integers(len(self.tasks)))
                v = self.base[k] + rng.uniform(-1.0, 1.0, len(self.low)) * self.reach
                values = tuple(float(x) for x in np.clip(v, self.low, self.high))
                try:
                    self.world.with_parameters(self.tasks[k].scene, values)
                except InvalidScene:
                    continue
                out.append((k, values))
                break
            else:
                raise UserError(
                    f"no valid scene in {MAX_DRAWS} draws near the tasks: widen the spread"
                )
        return out

    def task(self, k: int, values: Sequence[float]) -> Task:
        """Training task k with its parameters set to `values`."""
        t = self.tasks[k]
        return t.with_scene(self.world.with_parameters(t.scene, values))

    def features(self, cands: Sequence[tuple[int, tuple[float, ...]]]) -> np.ndarray:
        """float32 (n, K + 2P): the task one-hot, the values and their offsets from the
        task's own, each as a share of its range."""
        k = np.array([c[0] for c in cands], int)
        v = np.array([c[1] for c in cands], np.float64).reshape(len(cands), -1)  # (n, P)
        span = self.high - self.low
        x = np.zeros((len(cands), len(self.tasks) + 2 * len(self.low)), np.float32)
        x[np.arange(len(cands)), k] = 1.0
        x[:, len(self.tasks) : len(self.tasks) + len(self.low)] = (v - self.low) / span
        x[:, len(self.tasks) + len(self.low) :] = (v - self.base[k]) / span
        return x

    def offsets(self, cands: Sequence[tuple[int, tuple[float, ...]]]) -> np.ndarray:
        """float64 (n, P): each value's offset from its task's own, as a share of the reach."""
        k = np.array([c[0] for c in cands], int)
        v = np.array([c[1] for c in cands], np.float64).reshape(len(cands), -1)
        return (v - self.base[k]) / np.where(self.reach > 0, self.reach, 1.0)

    def cell(self, p: Probe) -> tuple[int, ...]:
        """The probe's task and grid cell (distinct failures are distinct cells)."""
        share = (np.array(p.values) - self.low) / (self.high - self.low)
        return (p.task, *np.minimum((share * CELLS).astype(int), CELLS - 1).tolist())


def probe(
    world: World, act: Act, hoods: Neighbourhoods, cands: Sequence[tuple[int, tuple[float, ...]]]
) -> list[Probe]:
    """Roll the policy out on each candidate's scene in lockstep; where it fails, the
    expert's demonstration (a Benchmark's) says whether the scene could be done at all."""
    tasks = [hoods.task(k, v) for k, v in cands]
    runs = roll(world, act, tasks, [t.scene for t in tasks])
    out = []
    for (k, _), t, r in zip(cands, tasks, runs, strict=True):
        expert_failed = False
        if not r.success and world.benchmark:
            expert_failed = not world.demonstrate(t).success  # type: ignore[attr-defined]
        v = tuple(world.parameters_of(t.scene))  # as placed (DoorKey: on its rows)
        out.append(Probe(k, v, not r.success and not expert_failed, expert_failed))
    return out


def uniform(
    world: World, act: Act, hoods: Neighbourhoods, config: SceneSearch, seed: int
) -> list[Probe]:
    """`budget` probes drawn uniformly from the neighbourhoods (seeded)."""
    rng = np.random.default_rng([seed, 31])
    cands = hoods.draw(rng, config.budget)
    out: list[Probe] = []
    for i in range(0, len(cands), config.batch):
        out += probe(world, act, hoods, cands[i : i + config.batch])
    return out


def surrogate(
    world: World, act: Act, hoods: Neighbourhoods, config: SceneSearch, seed: int
) -> list[Probe]:
    """`start` uniform probes, then batches picked by a refitted random forest (seeded)."""
    from sklearn.ensemble import RandomForestClassifier

    rng = np.random.default_rng([seed, 37])
    out = probe(world, act, hoods, hoods.draw(rng, min(config.start, config.budget)))
    while len(out) < config.budget:
        n = min(config.batch, config.budget - len(out))
        pool = hoods.draw(rng, config.pool)
        y = np.array([p.failed for p in out])
        if y.any() and not y.all():
            x = hoods.features([(p.task, p.values) for p in out])
            forest = RandomForestClassifier(
                n_estimators=config.trees, random_state=int(rng.integers(2**31)), n_jobs=1
            ).fit(x, y)
            per_tree = np.stack(
                [t.predict_proba(hoods.features(pool))[:, 1] for t in forest.estimators_]
            )  # (trees, pool)
            score = per_tree.mean(0) + config.explore * per_tree.std(0)
        else:  # nothing to tell apart yet: the pool's order is uniform
            score = np.zeros(len(pool))
        score = score + rng.random(len(pool)) * 1e-6
        out += probe(world, act, hoods, _spread_picks(hoods, out, pool, score, n, config.diverse))
    return out


def _spread_picks(hoods, probes, pool, score, n: int, weight: float) -> list:
    """n candidates of the pool picked one at a time by score + weight x the distance to the
    nearest probe or pick so far (of the same task; 1 where there is none)."""
    where = lambda cands: hoods.offsets(cands)  # noqa: E731 (n, P) in neighbourhood shares
    xs, ks = where(pool), np.array([c[0] for c in pool])
    near = np.ones(len(pool))
    done = [(p.task, p.values) for p in probes]
    if done:
        seen, sk = where(done), np.array([c[0] for c in done])
        for k in np.unique(ks):
            mine = ks == k
            if (sk == k).any():
                d = np.linalg.norm(xs[mine][:, None] - seen[sk == k][None], axis=2)
                near[mine] = np.minimum(1.0, d.min(1))
    picked: list[int] = []
    for _ in range(n):
        total = score + weight * near
        total[picked] = -np.inf
        j = int(np.argmax(total))
        picked.append(j)
        same = ks == ks[j]
        near[same] = np.minimum(near[same], np.linalg.norm(xs[same] - xs[j], axis=1))
    return [pool[j] for j in picked]


SEARCHES = {"uniform": uniform, "surrogate": surrogate}


def curve(probes: Sequence[Probe]) -> list[int]:
    """Failures found after each probe."""
    return np.cumsum([p.failed for p in probes]).tolist()


def distinct(hoods: Neighbourhoods, probes: Sequence[Probe]) -> int:
    """Distinct failing cells among the probes."""
    return len({hoods.cell(p) for p in probes if p.failed})


__all__ = [
    "SEARCHES",
    "Neighbourhoods",
    "Probe",
    "SceneSearch",
    "curve",
    "distinct",
    "probe",
    "surrogate",
    "uniform",
]
