"""The options of `dfa experiment positions` (PositionsArgs). Light to import."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class PositionsArgs:
    """Search a world's continuous scene parameters (where objects stand) for failures.

    Near TASKS training tasks (seeds 0, 1, ...), each parameter the world declares
    (World.scene_parameters; nav2d: the goal's and the agent's x and y, the tabletop: the
    object's and the goal's, DoorKey: the key's, door's and goal's rows) moved by up to SPREAD
    of its range: a random-forest surrogate refitted as outcomes come in (FATE's manner)
    against uniform sampling of the same neighbourhoods, BUDGET rollouts each, over SEEDS seeds
    (a failure: the policy fails the task where the world's expert does not). The first
    DIAGNOSE failures the surrogate found on seed 0 (the first in each distinct cell,
    search.scene_search.Neighbourhoods.cell) are diagnosed by the counterfactual search
    against the expert's demonstration (edits of up to 2 concept changes), the minimal edit
    replayed to see whether it restores success.

    Writes OUT/<world>.json, then OUT/table.md and OUT/failures.png from every world's JSON in
    OUT (run it once per world into the same folder).
    """

    world: str = "nav2d"
    """A registered world that declares scene parameters."""
    policy: str | None = None
    """The policy instead of the base policy (a checkpoint folder, onnx:, torch:, sb3:)."""
    budget: int = 200
    """Rollouts per search and seed."""
    seeds: int = 5
    """Seeds of each search."""
    tasks: int = 8
    """Training tasks whose neighbourhoods are searched."""
    spread: float = 0.05
    """How far each parameter moves from the task's own value, as a share of its range."""
    diagnose: int = 5
    """Failures diagnosed by the counterfactual search (0: none)."""
    max_candidates: int | None = None
    """The counterfactual search's candidate limit per failure (default: the world's)."""
    out: Path = Path("docs/results/sweep/continuous")
    """The results folder."""
    progress: bool = True
    """Show progress."""
