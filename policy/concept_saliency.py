"""The concepts of a failed test task ranked by a saliency method (policy.saliency).

A method's maps are reduced to one score per concept a person can point at in the scene
(sim.core.visible.visible_concepts): the attribution inside the pixels of the objects that
show it (shown_slots; their masks from the renderer, per step), summed over the steps of the
failed rollout that the demonstration has an action for. The presence of a kind with no
object in the scene has no pixels, so no map can point at it: its score is 0.

Concepts of one object (its colour, its shape, its presence) share its pixels and so its
score: a saliency map can name an object, not which of its concepts matters. Such ties are
broken at random (seeded), so a ranking says no more than the map does; the object-level
reading, whether the first concept belongs to the right object, is kept beside it
(`Ranking.groups`).

Readings (READINGS): "abs", the magnitude of every pixel's attribution summed inside the object
(a map's usual reading: where the output depends on the frame); "signed", the attribution with
its sign, negated, summed inside the object: the object whose pixels push the policy's output
away from the demonstrated action most is blamed first. Spans (SPANS): every explained step
("all"), or the steps before the failed rollout leaves the demonstration ("before", `Frames.
before`: the leading steps whose frames are the demonstration's, the first step of a different
action included; in a continuous world a frame counts as the demonstration's while at most
DIVERGED of its pixels differ, since the actions never agree to the bit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from policy.methods import check_method
from policy.model import Policy
from policy.saliency import SaliencyConfig, attributions, explained_steps, feature_labels
from sim.core import Task, Trajectory, UserConcept, World
from sim.core.visible import shown_slots, slot_masks, visible_concepts

READINGS = ("abs", "signed")
"""How a map's pixels are summed inside an object: magnitudes, or the blame (minus the sign)."""
SPANS = ("all", "before")
"""Which steps are summed: all explained ones, or those before the rollout diverges."""
DIVERGED = 0.01
"""A continuous world's frame has left the demonstration's when more of its pixels differ."""


@dataclass(frozen=True, eq=False)
class Frames:
    """What every saliency ranking of one failed rollout shares."""

    concepts: tuple[UserConcept, ...]
    """The concepts visible in the test scene, in the space's order (K of them)."""
    groups: tuple[tuple[str, ...], ...]
    """Per concept: the slots whose pixels show it (concepts of one object share them)."""
    obs: np.ndarray  # (T, H, W, 3) uint8: the failed rollout's frames that are explained
    actions: np.ndarray  # (T, A) float32 or (T,) int64: the demonstrated actions at those steps
    masks: np.ndarray  # (K, T, H, W) bool: each concept's pixels per step
    features: np.ndarray  # (T, H, W) int64: object labels for KernelSHAP (feature_labels)
    before: int = 0
    """The leading steps before the rollout diverges from the demonstration (1 .. T; 0: T)."""

    def steps(self, span: str) -> int:
        """How many leading steps a span reads."""
        assert span in SPANS, span
        return len(self.obs) if span == "all" or not self.before else self.before


@dataclass(frozen=True)
class Ranking:
    """Every visible concept, the best explanation first."""

    concepts: tuple[str, ...]
    """User concept names ("goal.colour"), best first."""
    scores: tuple[float, ...]
    """The explainer's score of each, in the same order (larger is more to blame)."""
    groups: tuple[tuple[str, ...], ...]
    """The slots (object) each one is shown by, in the same order."""

    def rank_of(self, name: str) -> int | None:
        """1-based position of a concept, None when it is not ranked."""
        return self.concepts.index(name) + 1 if name in self.concepts else None


def prepare(world: World, task: Task, rollout: Trajectory, demo: Trajectory) -> Frames:
    """Frames of a failed rollout of `task` explained against `demo`: masks and labels."""
    steps = explained_steps(world, rollout, demo)
    scenes = list(rollout.scenes[:steps])
    concepts = visible_concepts(world.space, task.scene)
    groups = tuple(shown_slots(uc, task.scene) for uc in concepts)
    slot_index = {s.name: i for i, s in enumerate(world.space.slots)}
    per_slot = slot_masks(world, scenes)  # (T, S, H, W)
    h, w, _ = world.obs_shape
    masks = np.zeros((len(concepts), steps, h, w), bool)
    for k, group in enumerate(groups):
        for slot in group:
            masks[k] |= per_slot[:, slot_index[slot]]
    return Frames(
        concepts,
        groups,
        rollout.observations[:steps],
        demo.actions[:steps],
        masks,
        feature_labels(per_slot),
        before_divergence(world, rollout, demo),
    )


def before_divergence(world: World, rollout: Trajectory, demo: Trajectory) -> int:
    """The leading explained steps whose rollout frame is the demonstration's (at least 1: both
    start from the task's scene): equal frames in a discrete world, frames that differ in at
    most DIVERGED of their pixels in a continuous one."""
    steps = explained_steps(world, rollout, demo)
    for t in range(1, steps):
        differ = np.any(rollout.observations[t] != demo.observations[t], axis=-1)  # (H, W)
        if differ.any() if world.discrete else differ.mean() > DIVERGED:
            return t
    return max(steps, 1)


def concept_scores(frames: Frames, maps: np.ndarray, steps: int | None = None) -> np.ndarray:
    """float64 (K,): the attribution inside each concept's pixels over the first `steps` steps
    (None: all). maps: float32 (T, H, W) densities (policy.saliency.attribute) or blame."""
    assert maps.shape == frames.masks.shape[1:], (
        f"maps {maps.shape} and masks {frames.masks.shape[1:]} differ"
    )
    n = len(maps) if steps is None else steps
    return np.array(
        [float(maps[:n][m[:n]].sum(dtype=np.float64)) for m in frames.masks], np.float64
    )


def reading_map(unsigned: np.ndarray, signed: np.ndarray, reading: str) -> np.ndarray:
    """The per-pixel score a reading sums: the magnitude, or the blame (-signed)."""
    assert reading in READINGS, reading
    return unsigned if reading == "abs" else -signed


def ranked(frames: Frames, scores: np.ndarray, *, seed: int) -> Ranking:
    """The concepts by score, ties at random (seeded)."""
    draw = np.random.default_rng(seed).permutation(len(frames.concepts))
    order = sorted(range(len(frames.concepts)), key=lambda k: (-scores[k], draw[k]))
    return Ranking(
        tuple(frames.concepts[k].name for k in order),
        tuple(float(scores[k]) for k in order),
        tuple(frames.groups[k] for k in order),
    )


def saliency_ranking(
    policy: Policy,
    frames: Frames,
    method: str,
    *,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> Ranking:
    """The visible concepts ranked by `method`'s attribution inside their pixels (abs, all)."""
    return saliency_readouts(policy, frames, method, seed=seed, config=config)[("abs", "all")]


def frame_maps(
    policy: Policy,
    frames: Frames,
    method: str,
    *,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> tuple[np.ndarray, np.ndarray]:
    """(unsigned, signed) float32 (T, H, W): `method`'s maps of the frames."""
    check_method(method)
    return attributions(
        policy,
        frames.obs,
        frames.actions,
        method,
        features=frames.features if method == "kernel_shap" else None,
        seed=seed,
        config=config,
    )


def readouts(
    frames: Frames, unsigned: np.ndarray, signed: np.ndarray, *, seed: int
) -> dict[tuple[str, str], Ranking]:
    """(reading, span) -> the visible concepts ranked by that readout of the maps."""
    return {
        (reading, span): ranked(
            frames,
            concept_scores(frames, reading_map(unsigned, signed, reading), frames.steps(span)),
            seed=seed,
        )
        for reading in READINGS
        for span in SPANS
    }


def saliency_readouts(
    policy: Policy,
    frames: Frames,
    method: str,
    *,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> dict[tuple[str, str], Ranking]:
    """Every readout's ranking (READINGS x SPANS) from one run of `method`."""
    unsigned, signed = frame_maps(policy, frames, method, seed=seed, config=config)
    return readouts(frames, unsigned, signed, seed=seed)
