"""The options of `dfa export lerobot` (ExportArgs) and `dfa view` (ViewArgs). Light to
import: nothing here loads torch, MuJoCo, rerun, viser or the LeRobot libraries.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro


@dataclass(frozen=True)
class ExportArgs:
    """Write dfa's robot-learning data as a LeRobotDataset v3.0 folder, the dataset format
    LeRobot trains from (meta/info.json, parquet tables, AV1 videos for camera frames).

    `dfa export lerobot --from FOLDER --out DIR` reads a page session (session.jsonl), a
    `dfa sweep` folder (sweep.csv) or a `dfa experiment q2` results folder (runs.csv) and
    writes one episode per trajectory: the demonstration, each variant finetuned on, the
    counterfactual rollouts, the failed rollout and the finetuned one (a sweep: each example
    failure and the expert's demonstration of it; q2: each run's demonstration, variants and
    failed rollout), task = the instruction, with dfa's columns dfa.role, dfa.edit,
    dfa.concept, dfa.label, dfa.action_distance, dfa.scene and dfa.run. `dfa run --lerobot DIR`
    writes one run's. Read it back with `dfa view DIR` or `--demo lerobot:DIR:episode=N`.
    """

    format: tyro.conf.Positional[Literal["lerobot"]]
    """The dataset format (LeRobotDataset v3.0)."""
    source: Annotated[Path, tyro.conf.arg(name="from", metavar="FOLDER")]
    """A page session folder, a `dfa sweep` output folder or a q2 results folder."""
    out: Path
    """The dataset folder: new, empty, or a dataset this replaces once the new one is whole."""
    world: str | None = None
    """Only this world's runs (a session or q2 folder); a sweep's world (default: the sweep
    folder's name, as `dfa sweep` names it)."""
    policy: str | None = None
    """The policy the session or sweep ran, when not the base policy (as `dfa run --policy`)."""
    weights: Path | None = None
    """Finetuned weights for --policy (as `dfa run --weights`)."""
    fps: int = 10
    """Frames per second written in the dataset (its timestamps are frame / fps)."""
    frames: Literal["auto", "image", "video"] = "auto"
    """auto: AV1 video for a camera's frames (tabletop, Fetch), PNG images for frames drawn to
    the pixel (nav2d, doorkey, MiniGrid: lossless); or force one."""


@dataclass(frozen=True)
class ViewArgs:
    """Write every episode of a LeRobotDataset (anyone's, or one dfa exported) into one Rerun
    recording: the episodes side by side on one `step` timeline, a tab per episode (its frames,
    one plot per action dimension, its task and dfa's columns) after a tab of all of them (a
    grid of frames, every episode's actions per dimension). Open it with `rerun FILE`."""

    dataset: tyro.conf.Positional[Path]
    """The dataset folder (meta/info.json, data/, videos/)."""
    out: Path | None = None
    """The .rrd to write; default recordings/<dataset folder name>.rrd."""
    episodes: tuple[int, ...] = ()
    """Only these episodes (default: all, up to 500)."""
    camera: str | None = None
    """The image or video feature to show (default the first), e.g. main or
    observation.images.main."""
