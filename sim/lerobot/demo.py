"""An episode of a LeRobotDataset as the demonstration of a task: `--demo lerobot:DIR[:episode=N]`.

Checked as a demonstration .npz is (sim.core.demonstration): the episode's actions must be the
world's (kind, shape, finite, one per step of the horizon); an episode dfa wrote also names its
scenes (`dfa.scene`), and must start from the task's. Then its actions are replayed from the
task's scene through the world's own dynamics, and the episode's frames must be the frames that
replay renders: exactly for images (PNG is lossless), within the codec's error for video: the
mean colour of every block of pixels (a twelfth of the frame's side, at least 4) within
VIDEO_TOLERANCE of 255 (the AV1 encoding LeRobot uses moves it by at most about 40 on the
project's worlds, while one step of a moving agent or arm moves it by more; a world whose frames
barely change in a step is caught where the replay has drifted that far). The first step that
differs is named in one line. What is used from then on is the replay, as for a .npz.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.core.demonstration import check_actions
from sim.core.errors import UserError
from sim.core.scene import Scene
from sim.core.task import Task
from sim.core.trajectory import Trajectory
from sim.core.world import World
from sim.lerobot.episode import Episode
from sim.lerobot.reader import Dataset

PREFIX = "lerobot:"
SPEC = "lerobot:DIR[:episode=N][:camera=NAME]"
SCENE = "dfa.scene"  # the column of an episode dfa wrote that holds each frame's scene (JSON)
VIDEO_TOLERANCE = 64.0  # of 255: a block's mean colour, video frame against the replay's


@dataclass(frozen=True)
class DemoSpec:
    """Which episode of which dataset, and which camera's frames."""

    root: Path
    episode: int = 0
    camera: str | None = None

    @property
    def source(self) -> str:
        return f"{self.root} episode {self.episode}"


def is_spec(text: str | Path) -> bool:
    return str(text).startswith(PREFIX)


def parse(text: str | Path) -> DemoSpec:
    """lerobot:DIR[:episode=N][:camera=NAME] -> DemoSpec; a UserError saying the form."""
    body = str(text).removeprefix(PREFIX)
    parts = body.split(":")
    root, options = parts[0], parts[1:]
    episode, camera = 0, None
    for opt in options:
        key, _, value = opt.partition("=")
        if key == "episode" and value.isdigit():
            episode = int(value)
        elif key == "camera" and value:
            camera = value
        else:
            raise UserError(f"--demo {text}: {opt!r} is not an option; the form is {SPEC}")
    if not root:
        raise UserError(f"--demo {text}: no folder; the form is {SPEC}")
    return DemoSpec(Path(root), episode, camera)


def read(spec: DemoSpec) -> tuple[Episode, bool]:
    """The episode, and whether its frames are lossless images (else video)."""
    ds = Dataset(spec.root)
    key = ds.camera(spec.camera)
    return ds.episode(spec.episode, camera=key), ds.features[key]["dtype"] == "image"


def scenes_of(episode: Episode, *, source: str) -> tuple[Scene, ...] | None:
    """The scenes an episode dfa wrote names (None for an episode without them)."""
    texts = episode.columns.get(SCENE)
    if texts is None:
        return None
    try:
        return tuple(Scene.from_dict(json.loads(str(t))) for t in texts)
    except (ValueError, TypeError, KeyError, AssertionError, UserError) as e:
        raise UserError(f"{source}: its {SCENE} column is not a scene ({e})") from None


def first_scene(spec: DemoSpec) -> Scene:
    """The scene the episode starts from (a task for a world without test tasks)."""
    episode, _ = read(spec)
    scenes = scenes_of(episode, source=spec.source)
    if scenes is None:
        raise UserError(
            f"{spec.source}: names no scenes (no {SCENE} column), so it cannot say which task it "
            "demonstrates; a world without test tasks needs a dataset dfa exported"
        )
    return scenes[0]


def blocks(frames: np.ndarray, side: int) -> np.ndarray:
    """The mean colour of each side x side block of (T, H, W, 3) frames: (T, H/side, W/side, 3)."""
    t, h, w, c = frames.shape
    h, w = h // side * side, w // side * side
    cut = frames[:, :h, :w].astype(np.float32)
    return cut.reshape(t, h // side, side, w // side, side, c).mean(axis=(2, 4))


def frame_mismatch(want: np.ndarray, got: np.ndarray, *, lossless: bool) -> tuple[int, str] | None:
    """The first step whose frame differs (exactly; for video, some block's mean colour beyond
    VIDEO_TOLERANCE) and how."""
    if lossless:
        for t, (a, b) in enumerate(zip(want, got, strict=True)):
            diff = np.abs(a.astype(np.int16) - b.astype(np.int16))
            if diff.any():
                return (
                    t,
                    f"{int((diff > 0).sum())} of {diff.size} values differ, by up to {diff.max()}",
                )
        return None
    side = max(4, min(want.shape[1:3]) // 12)
    diff = np.abs(blocks(want, side) - blocks(got, side)).max(axis=-1)  # (T, h, w)
    worst = diff.reshape(len(diff), -1).max(axis=1)
    over = np.flatnonzero(worst > VIDEO_TOLERANCE)
    if not len(over):
        return None
    t = int(over[0])
    return t, (
        f"a {side}x{side}-pixel block's mean colour differs by {worst[t]:.0f} of 255; "
        f"video allows {VIDEO_TOLERANCE:.0f}"
    )


def demonstration(world: World, task: Task, spec: DemoSpec) -> Trajectory:
    """The episode's actions replayed from the task's scene, once it has passed every check."""
    episode, lossless = read(spec)
    source = spec.source
    actions = episode.actions
    if world.discrete and actions.ndim == 2 and actions.shape[1] == 1:
        actions = actions[:, 0]
    if not world.discrete and actions.ndim == 1:  # one number a step: a plain column
        actions = actions[:, None]
    actions = check_actions(world, actions, source=source)
    if episode.frames.shape[1:] != world.obs_shape:
        raise UserError(
            f"{source}: frames of shape {episode.frames.shape[1:]}, but {world.name} renders "
            f"{world.obs_shape}"
        )
    scenes = scenes_of(episode, source=source)
    if scenes is not None:
        other = sorted({s.world for s in scenes} - {world.name})
        if other:
            raise UserError(f"{source}: its scenes belong to {', '.join(other)}, not {world.name}")
        if scenes[0] != task.scene:
            raise UserError(f"{source}: the episode starts from another scene than the task")
    replay = world.replay(task, actions)
    n = min(episode.length, len(replay.observations))
    bad = frame_mismatch(replay.observations[:n], episode.frames[:n], lossless=lossless)
    if bad is not None:
        t, how = bad
        after = "the task's start" if t == 0 else f"actions 0 to {t - 1} replayed from the start"
        raise UserError(
            f"{source}: frame {t} is not what {world.name} shows after {after} ({how}); "
            "the episode does not demonstrate this task"
        )
    return replay


def trajectory(world: World, episode: Episode, *, source: str) -> Trajectory:
    """An episode dfa wrote, as the trajectory it was made from: its scenes (dfa.scene) and
    frames, and the scene after its last action (one step of the world, rendered)."""
    scenes = scenes_of(episode, source=source)
    if scenes is None:
        raise UserError(f"{source}: names no scenes (no {SCENE} column); dfa did not write it")
    actions = episode.actions
    if world.discrete:
        actions = actions.reshape(len(actions)).astype(np.int64)
    else:
        actions = actions.reshape(len(actions), -1).astype(np.float32)
    last = world.step_batch([scenes[-1]], actions[-1:])[0]
    frames = np.concatenate([episode.frames, world.render_batch([last])])  # (T+1, H, W, 3)
    return Trajectory((*scenes, last), frames, actions, episode.success)
