"""Roll many edited scenes out in lockstep against a demonstration, dropping early."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from policy.model import Policy, probabilities
from search.pauses import paused
from sim.core import Edit, Scene, Task, Trajectory, UserError, World


@dataclass(frozen=True, eq=False)
class Candidate:
    """One edit tried by the search.

    distances: float32 (T,) per-step action distance to the demonstration (L1 for continuous
        worlds; 1 - p(demonstrated action) for discrete ones); NaN after the candidate was
        dropped and at steps after the demonstration ended.
    matches: bool (T,) whether the step was within the bound (exact match when discrete).
    dropped_at: None when the edit is valid; else the first step that broke the bound, or,
        where the world's counterfactual "succeeds", the step its failed rollout ended.
    """

    edit: Edit
    distances: np.ndarray  # (T,) float32
    matches: np.ndarray  # (T,) bool
    dropped_at: int | None

    @property
    def valid(self) -> bool:
        return self.dropped_at is None

    @property
    def total(self) -> float:
        """Summed action distance over the steps it was rolled out."""
        return float(np.nansum(self.distances))

    def to_dict(self) -> dict:
        return {
            "edit": self.edit.to_list(),
            "valid": self.valid,
            "dropped_at": self.dropped_at,
            "distances": [None if np.isnan(d) else round(float(d), 6) for d in self.distances],
        }

    @classmethod
    def from_dict(cls, d: dict) -> Candidate:
        """Read back `to_dict` (matches: the steps before the drop; UserError if malformed)."""
        try:
            distances = np.array(
                [np.nan if v is None else float(v) for v in d["distances"]], np.float32
            )  # (T,)
            dropped = d["dropped_at"]
            if dropped is not None and (isinstance(dropped, bool) or not isinstance(dropped, int)):
                raise TypeError(f"dropped_at {dropped!r} is not a step")
            matches = ~np.isnan(distances)
            if dropped is not None:
                matches[int(dropped) :] = False
            return cls(Edit.from_list(d["edit"]), distances, matches, dropped)
        except (KeyError, TypeError, ValueError) as e:
            raise UserError(f"malformed candidate ({type(e).__name__}: {e})") from None


def compared_steps(world: World, demo: Trajectory) -> int:
    """Steps at which actions are compared: up to the demonstration's end (done) or horizon."""
    for t in range(demo.horizon):
        if world.done(demo.scenes[t]):
            return t
    return demo.horizon


@paused
def rollout_lockstep(
    world: World,
    policy: Policy,
    scene: Scene,
    demo: Trajectory,
    edits: Sequence[Edit],
    *,
    epsilon: float,
    task: Task | None = None,
) -> list[Candidate]:
    """Roll the policy out from every edited scene at once and compare with the demonstration.

    Each step: one batched render of the live candidates, one batched forward pass, one
    vectorised dynamics step. Where the world's counterfactual "follows" the demonstration, a
    candidate is dropped the first step its action leaves the bound (L1 < epsilon for
    continuous worlds, exact match for discrete ones). Where it "succeeds", every candidate is
    rolled out to the end and is valid when R' of `task` (default: `world.task_for(scene)`)
    holds on its states; a failed one is dropped at the step its rollout ended.
    """
    n, horizon = len(edits), demo.horizon
    steps = compared_steps(world, demo)
    follows = world.counterfactual == "follows"
    distances = np.full((n, horizon), np.nan, np.float32)
    matches = np.zeros((n, horizon), bool)
    dropped = np.full(n, -1, np.int64)
    live = np.arange(n)
    scenes = world.apply_batch(scene, edits)
    history = [[s] for s in scenes]  # each candidate's states, for R' ("succeeds")
    for t in range(steps):
        if len(live) == 0:
            break
        obs = world.render_batch(scenes)  # (L, H, W, 3)
        out = policy.outputs(obs)  # (L, A) actions or logits
        if world.discrete:
            acts = out.argmax(axis=1)  # (L,)
            target = int(demo.actions[t])
            dist = 1.0 - probabilities(out)[:, target]
            ok = acts == target
        else:
            acts = out
            dist = np.abs(out - demo.actions[t][None]).sum(axis=1)  # (L,)
            ok = dist < epsilon
        distances[live, t] = dist
        matches[live, t] = ok
        keep = np.arange(len(live))
        if follows:
            dropped[live[~ok]] = t
            keep = np.flatnonzero(ok)
        live = live[keep]
        if len(live) and (t + 1 < steps or not follows):
            scenes = world.step_batch([scenes[i] for i in keep], acts[keep])
            for k, s in zip(live, scenes, strict=True):
                history[k].append(s)
    if not follows:
        task = task or world.task_for(scene)
        for i in range(n):
            if not world.success(task, history[i]):
                dropped[i] = len(history[i]) - 1
    return [
        Candidate(edits[i], distances[i], matches[i], None if dropped[i] < 0 else int(dropped[i]))
        for i in range(n)
    ]


def distance_to_demo(world: World, traj: Trajectory, demo: Trajectory) -> np.ndarray:
    """float64 (T,): a rollout's per-step action distance to the demonstration (L1 for
    continuous actions; 0 or 1, whether the actions differ, for discrete ones); NaN at the
    steps after the demonstration ended, which are not compared."""
    a = traj.actions.reshape(traj.horizon, -1).astype(np.float64)  # (T, A)
    b = demo.actions.reshape(demo.horizon, -1).astype(np.float64)  # (T, A)
    d = (a != b).any(axis=1).astype(np.float64) if world.discrete else np.abs(a - b).sum(axis=1)
    d[compared_steps(world, demo) :] = np.nan
    return d
