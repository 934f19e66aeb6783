"""The options of `dfa study new|serve|analyse`. Light to import: nothing here loads torch,
MuJoCo, rerun or viser.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro


@dataclass(frozen=True)
class NewStudyArgs:
    """Make a user study's tasks once and freeze them in a folder (the paper's user study).

    The protocol (a TOML file) names the tasks per world and shift kind (the paper's: one per
    kind in nav2d and DoorKey, two in the tabletop, TI and TR half and half), the conditions
    (none, counterfactual, saliency, both), the design (between or within subjects) and a seed.
    Every task (the failed rollout, the demonstration, the counterfactual, the saliency maps)
    is computed here, so every participant sees the same ones. It issues the participant
    codes to hand out (OUT/codes.txt). Then `dfa study serve OUT`.
    """

    out: Path
    """The new study folder."""
    protocol: Path | None = None
    """study.toml (see README "Running a user study"); left out: the paper's protocol with
    conditions none and counterfactual, between subjects (as the paper's), seed 0."""
    participants: Annotated[int, tyro.conf.arg(metavar="INT")] = 24
    """How many participant codes to issue (OUT/codes.txt, printed): the study page accepts
    only these, one participant each."""


@dataclass(frozen=True)
class ServeStudyArgs:
    """Serve a frozen study to participants: each tab enters a code issued by `dfa study new`
    (OUT/codes.txt; no other is accepted), goes through
    the familiarisation and answers every question; answers are on disk before the page moves
    on, and a code entered again resumes at its first unanswered question."""

    folder: tyro.conf.Positional[Path]
    """The study folder (`dfa study new`)."""
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None
    """When left out, 8080 or the next free one; a port given must be free (0: any)."""
    host: str = "127.0.0.1"
    """The interface to bind; 0.0.0.0 exposes the page to the network."""


@dataclass(frozen=True)
class AnalyseStudyArgs:
    """Score a study's answers by the paper's rule and compare the conditions: accuracy per
    world, shift kind and condition with standard errors beside the paper's, chi-squared (1)
    between conditions per world, a mixed-effects logistic model (participant and task random)
    and an exact test by task, Wilcoxon signed-rank between TR and TI answers, each answer's
    provenance. Writes FOLDER/analysis/answers.csv, accuracy.md, accuracy.png, durations.png
    and answers.rrd."""

    folder: tyro.conf.Positional[Path]
    """The study folder."""
