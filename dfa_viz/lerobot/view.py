"""`dfa view DIR`: every episode of a LeRobotDataset (anyone's, or one dfa exported) in one
Rerun recording, side by side on one `step` timeline (step = the frame's index in its episode).

    episodes/eNNN/frame          the episode's frames (lossless for image features; video
                                 frames as decoded, JPEG-compressed like the run recordings')
    episodes/eNNN/info           the task, the length, success; dfa's role, edit, concepts and
                                 marks where the dataset has them (Markdown)
    actions/<k>/eNNN             action dimension k of episode NNN (a series per episode, so a
                                 plot per dimension shows every episode and one tab one)
    action_distance/eNNN         dfa.action_distance, where the dataset has it

The blueprint is the episode picker: a first tab with up to GRID episodes' frames in a grid and
a plot per action dimension over all of them, then a tab per episode (its frames, its actions
one plot per dimension, its text). Colours follow dfa's roles where the dataset names them.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from dfa_viz.charts import rgb
from dfa_viz.rrd import RrdFile, send_blueprint
from sim.core import UserError
from sim.lerobot import Dataset, Episode
from sim.lerobot.format import ACTION

GRID = 16  # episodes in the first tab's grid
MAX_EPISODES = 500  # without --episodes, a larger dataset is refused (choose some)
JPEG_QUALITY = 90
PALETTE = ("#1c7ed6", "#d9480f", "#2f9e44", "#ae3ec9", "#f08c00", "#0c8599", "#e64980", "#5c940d")
ROLE_COLOURS = {"variant": "#ae3ec9"}


@dataclass(frozen=True)
class Viewed:
    path: Path
    episodes: int
    frames: int


def entity(i: int) -> str:
    return f"e{i:03d}" if i < 1000 else f"e{i}"


def action_names(ds: Dataset, dims: int) -> list[str]:
    names = ds.features.get(ACTION, {}).get("names")
    if isinstance(names, list) and len(names) == dims:
        return [str(n) for n in names]
    if isinstance(names, dict):  # LeRobot's older {"motors": [...]} form
        flat = [str(n) for v in names.values() for n in v]
        if len(flat) == dims:
            return flat
    return ["action"] if dims == 1 else [f"action {k}" for k in range(dims)]


def colour(ep: Episode, i: int) -> list[int]:
    role = ep.text("dfa.role")
    if role in ROLE_COLOURS:
        h = ROLE_COLOURS[role]
        return [int(h[k : k + 2], 16) for k in (1, 3, 5)]
    if role:
        return rgb(role)
    h = PALETTE[i % len(PALETTE)]
    return [int(h[k : k + 2], 16) for k in (1, 3, 5)]


def title(ep: Episode, i: int) -> str:
    role = ep.text("dfa.role")
    mark = "✓" if ep.success else "✗"
    return f"{i} · {role} {mark}" if role else f"episode {i} {mark}"


def info_text(ds: Dataset, ep: Episode, i: int) -> str:
    lines = [f"**episode {i}** of {ds.root.name}: {ep.length} frames at {ds.fps} fps", ""]
    lines.append(f"- task: {ep.task}")
    lines.append(f"- success: {'yes' if ep.success else 'no'}")
    for name in ("dfa.role", "dfa.edit", "dfa.concept", "dfa.label", "dfa.run"):
        value = ep.text(name)
        if value:
            lines.append(f"- {name.removeprefix('dfa.')}: {value}")
    return "\n".join(lines)


def chosen(ds: Dataset, episodes: Sequence[int]) -> list[int]:
    if episodes:
        for n in episodes:
            ds.check_index(n)
        return list(dict.fromkeys(episodes))
    if len(ds) > MAX_EPISODES:
        raise UserError(
            f"{ds.root} has {len(ds)} episodes; one recording shows at most {MAX_EPISODES}: "
            "choose some with --episodes"
        )
    return list(range(len(ds)))


def blueprint(shown: list[tuple[int, Episode]], names: list[str]) -> rrb.Blueprint:
    grid = rrb.Grid(
        *(
            rrb.Spatial2DView(origin=f"/episodes/{entity(i)}/frame", name=title(ep, i))
            for i, ep in shown[:GRID]
        )
    )
    dims = rrb.Tabs(
        *(rrb.TimeSeriesView(origin=f"/actions/{k}", name=name) for k, name in enumerate(names))
    )
    overview = rrb.Vertical(grid, dims, name="all episodes", row_shares=[3, 2])
    tabs = []
    for i, ep in shown:
        e = entity(i)
        plots = [
            rrb.TimeSeriesView(origin="/", contents=[f"/actions/{k}/{e}"], name=name)
            for k, name in enumerate(names)
        ]
        tabs.append(
            rrb.Horizontal(
                rrb.Spatial2DView(origin=f"/episodes/{e}/frame", name=title(ep, i)),
                rrb.Vertical(*plots, rrb.TextDocumentView(origin=f"/episodes/{e}/info")),
                name=title(ep, i),
            )
        )
    return rrb.Blueprint(
        rrb.Tabs(overview, *tabs),
        rrb.TimePanel(state="collapsed", timeline="step", play_state="paused"),
        collapse_panels=True,
    )


def write_view(
    root: str | Path,
    path: str | Path,
    *,
    episodes: Sequence[int] = (),
    camera: str | None = None,
) -> Viewed:
    """Write the recording of `root`'s episodes (all, or `episodes`) to `path`."""
    ds = Dataset(root)
    key = ds.camera(camera)
    lossless = ds.features[key]["dtype"] == "image"
    picked = chosen(ds, episodes)
    rid = uuid.uuid5(uuid.NAMESPACE_URL, f"dfa/lerobot/{Path(root).resolve()}/{len(ds)}")
    file = RrdFile(path, rid)
    rec = file.rec
    shown: list[tuple[int, Episode]] = []
    frames = 0
    names: list[str] = []
    try:
        rec.send_recording_name(f"{ds.root.name} · {len(picked)} episodes")
        rec.send_property(
            "dataset",
            rr.AnyValues(
                root=str(ds.root), robot_type=ds.robot_type or "", fps=ds.fps, episodes=len(ds)
            ),
        )
        for i in picked:
            ep = ds.episode(i, camera=key)
            shown.append((i, _light(ep)))
            names = _log_episode(rec, ds, ep, i, lossless=lossless)
            frames += ep.length
        send_blueprint(rec, blueprint(shown, names))
    except BaseException:
        file.close(keep=False)
        raise
    file.close()
    return Viewed(Path(path), len(picked), frames)


def _light(ep: Episode) -> Episode:
    """What the blueprint needs of an episode (its title), without its frames."""
    cols = {k: ep.columns[k][:1] for k in ("dfa.role",) if k in ep.columns}
    return Episode(ep.task, ep.frames[:1], ep.actions[:1], ep.success, cols)


def _log_episode(rec: rr.RecordingStream, ds: Dataset, ep: Episode, i: int, *, lossless: bool):
    e = entity(i)
    rec.reset_time()
    for t, frame in enumerate(ep.frames):
        rec.set_time("step", sequence=t)
        img = rr.Image(frame)
        rec.log(f"episodes/{e}/frame", img if lossless else img.compress(JPEG_QUALITY))
    rec.log(
        f"episodes/{e}/info",
        rr.TextDocument(info_text(ds, ep, i), media_type="text/markdown"),
        static=True,
    )
    rec.log(f"episodes/{e}/success", rr.AnyValues(success=ep.success), static=True)
    steps = np.arange(ep.length)
    actions = ep.actions.reshape(ep.length, -1).astype(np.float64)  # (T, A)
    names = action_names(ds, actions.shape[1])
    c = colour(ep, i)
    for k in range(actions.shape[1]):
        where = f"actions/{k}/{e}"
        rec.send_columns(
            where,
            indexes=[rr.TimeColumn("step", sequence=steps)],
            columns=rr.Scalars.columns(scalars=actions[:, k]),
        )
        rec.log(where, rr.SeriesLines(names=f"{i}: {names[k]}", colors=c), static=True)
    dist = ep.columns.get("dfa.action_distance")
    if dist is not None:
        d = np.asarray(dist, np.float64)
        keep = d >= 0  # -1: a step the demonstration does not have
        if keep.any():
            rec.send_columns(
                f"action_distance/{e}",
                indexes=[rr.TimeColumn("step", sequence=steps[keep])],
                columns=rr.Scalars.columns(scalars=d[keep]),
            )
            rec.log(f"action_distance/{e}", rr.SeriesLines(names=f"{i}", colors=c), static=True)
    return names
