"""Writing dfa's data as a LeRobotDataset: a run (`dfa run --lerobot DIR`) or a folder
(`dfa export lerobot --from FOLDER --out DIR`: a page session, a sweep, a q2 results folder).

Frames are AV1 video as LeRobot encodes them when they are a camera's (a world without
lossless_frames: tabletop, Fetch), and PNG images in the tables otherwise (the 36x36 worlds,
MiniGrid: lossless, every pixel as the world drew it, where a video codec would smear objects a
few pixels across).
`--frames image|video` chooses; video needs PyAV with an AV1 encoder (else images, and the
command says so). robot_type is the world's name.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import chain
from pathlib import Path

from dfa_viz.lerobot import sources as S
from dfa_viz.lerobot.args import ExportArgs
from dfa_viz.lerobot.episodes import run_episodes
from dfa_viz.run_record import RunRecord
from sim import get_world
from sim.core import UserError, World
from sim.lerobot import Episode, Written, write_dataset
from sim.lerobot.video import encoder_available
from sim.lerobot.writer import check_out


@dataclass(frozen=True)
class Exported:
    written: Written
    note: str
    """Why the frames are what they are (one line)."""

    def summary(self) -> str:
        w = self.written
        frames = "AV1 video" if w.video else "PNG images"
        return (
            f"{w.root}: a LeRobotDataset v3.0, {w.episodes} episodes, {w.frames} frames "
            f"({frames}; {self.note}), {w.bytes / 1e6:.2f} MB"
        )


def video_for(world: World, frames: str) -> tuple[bool, str]:
    """Whether a world's frames go as video, and why, in a few words."""
    h, w = world.obs_shape[:2]
    if frames == "image":
        return False, "--frames image"
    if frames == "auto" and world.lossless_frames:
        return False, f"{h}x{w} frames drawn to the pixel, kept as lossless images"
    if not encoder_available():
        return False, "video wanted, but PyAV has no AV1 encoder here: images instead"
    return True, "--frames video" if frames == "video" else f"{h}x{w} camera frames"


def write(
    out: Path, world: World, episodes: Iterable[Episode], *, fps: int, frames: str
) -> Exported:
    video, note = video_for(world, frames)
    written = write_dataset(
        out,
        episodes,
        fps=fps,
        robot_type=world.name,
        video=video,
        action_names=world.action_names,
    )
    return Exported(written, note)


def export_run(
    out: Path, world: World, record: RunRecord, *, known=(), fps: int = 10, frames: str = "auto"
) -> Exported:
    """A run's trajectories (episodes.run_episodes) as a dataset at `out`."""
    eps = run_episodes(world, record, known=known)
    if not eps:
        raise UserError("the run has no trajectories to export")
    return write(out, world, eps, fps=fps, frames=frames)


def _one_world(
    pairs: Iterator[tuple[World, Episode]], wanted: str | None
) -> tuple[World, Iterator[Episode]]:
    """The first world's episodes (or `wanted`'s); a second world is one line."""
    chosen = ((w, e) for w, e in pairs if wanted is None or w.name == wanted)
    head = next(chosen, None)
    if head is None:
        raise UserError("nothing to export" + (f" in {wanted}" if wanted else ""))
    first = head[0]

    def rest() -> Iterator[Episode]:
        for w, e in chosen:
            if w.name != first.name:
                raise UserError(
                    f"runs in {first.name} and {w.name}: a dataset holds one world; "
                    "choose one with --world"
                )
            yield e

    return first, chain([head[1]], rest())


def export(args: ExportArgs) -> Exported:
    """`dfa export lerobot`."""
    check_out(args.out)
    if args.fps < 1:
        raise UserError(f"--fps must be at least 1, not {args.fps}")
    src = S.Source.of(args.source)
    policy_for = S.policies(args.policy, args.weights)
    if src.kind == "session":
        pairs = S.session_episodes(src.folder, policy_for)
    elif src.kind == "q2":
        if args.policy is not None or args.weights is not None:
            raise UserError("a q2 experiment ran the base policies; --policy does not apply")
        pairs = S.q2_episodes(src.folder)
    else:
        name = args.world or src.folder.name
        try:
            world = get_world(name)
        except UserError:
            raise UserError(
                f"--from {src.folder}: a sweep does not name its world; give --world"
            ) from None
        pairs = S.sweep_episodes(src.folder, world, policy_for)
    world, episodes = _one_world(pairs, args.world if src.kind != "sweep" else None)
    return write(args.out, world, episodes, fps=args.fps, frames=args.frames)
