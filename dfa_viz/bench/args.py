"""The options of `dfa bench` (BenchArgs). Light to import: nothing here loads torch, MuJoCo,
rerun or viser.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sim import PAPER_WORLDS

MINIGRID = "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12"  # measured with docs/examples' SB3 agent


@dataclass(frozen=True)
class BenchArgs:
    """Measure every speed figure on this machine and write them to benchmarks/ as Markdown.

    Each world's search against a naive one-candidate-at-a-time loop timed in the same
    process, a whole `dfa run`, the tabletop's edit + render and search targets, per world the
    render throughput, finetuning time, recording size and one experiment run, and the web page
    (load, slider latency, finetune round trip).
    """

    worlds: tuple[str, ...] = (*PAPER_WORLDS, MINIGRID)
    """Which worlds to measure (the MiniGrid one with the stable-baselines3 agent of
    docs/examples; a closed-loop MuJoCo world of dfa_viz.bench.run.BENCHES when named: its
    search alone, some minutes)."""
    repeats: int = 3
    """Timing repeats (the best is reported)."""
    page: bool = True
    """Also measure the web page in Chromium (a minute or two)."""
    out: Path = Path("benchmarks") / "latest.md"
    """The Markdown report."""
    prior_tasks: int = 100
    """Planted size-2 tasks per paper world on which the learned search prior is measured
    against enumeration and the first-step prior (dfa_viz.bench.prior)."""
