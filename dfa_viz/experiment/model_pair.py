"""`dfa experiment pair`: the explainer benchmark's model pair. Two policies of one architecture
that differ in one thing an explainer should see: nav2d's base policy, cloned where no
distractor ever appears, is thrown by one (its failing distractor_ti task); the same policy after
the loop's TI feedback (variants with and without the distractor, finetuned) is not.

The ground truth is behaviour, per seed: on the failed rollout's scenes, removing the distractor
(the counterfactual's edit) moves the base policy's actions by `moved_base` and the finetuned
one's by `moved_tuned`; the pair differs where moved_base > moved_tuned. On the same frames,
each saliency method's share of its attribution inside the distractor's pixels (by magnitude,
and of the blame: the attribution pushing the action away from the demonstration) is read for
both policies; an explainer tells the pair apart on a seed when it gives the base policy the
larger share, by at least MARGIN. Seeds are independent units; a table counts them per method
and reading.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence

import numpy as np

from dfa_viz.configs import AdaptConfig
from policy.methods import METHOD_NAMES
from sim.core import UserError, files

WORLD, SHIFT, SLOT = "nav2d", "distractor_ti", "distractor"
MARGIN = 0.01  # shares closer than this (a point of the attribution) are a tie, not a verdict
COLUMNS = (
    "seed",
    "task",
    "method",
    "reading",
    "share_base",
    "share_tuned",
    "moved_base",
    "moved_tuned",
    "apart",
)


def moved(world, policy, scenes: Sequence, edit) -> float:
    """Mean L1 distance between the policy's actions on the scenes and on them edited."""
    a = policy.act(world.render_batch(list(scenes)))  # (T, A)
    b = policy.act(world.render_batch([world.apply(s, edit) for s in scenes]))  # (T, A)
    return float(np.abs(a - b).sum(axis=1).mean())


def share(maps: np.ndarray, mask: np.ndarray) -> float:
    """The positive part of `maps` (T, H, W) inside `mask` (T, H, W) over all of it."""
    m = np.clip(maps.astype(np.float64), 0.0, None)
    total = m.sum()
    return float(m[mask].sum() / total) if total > 0 else float("nan")


def pair_rows(
    seed: int, *, config: AdaptConfig = AdaptConfig(), methods: Sequence[str] = METHOD_NAMES
) -> list[dict]:
    """One seed: the pair made by the loop, its behaviour and each method's shares."""
    from dfa_viz.experiment.explain import task_id
    from dfa_viz.loop import run_loop
    from dfa_viz.users import SimulatedUser
    from policy import base_policy, failing_test_task
    from policy.concept_saliency import READINGS, frame_maps, prepare, reading_map
    from sim import get_world

    world = get_world(WORLD)
    base = base_policy(world)
    task, _ = failing_test_task(world, base, SHIFT, seed)
    record = run_loop(world, base, task, SimulatedUser(world, seed=seed), seed=seed, config=config)
    d, ad = record.diagnosis, record.adaptation
    if d is None or d.edit is None or ad is None or ad.policy is None:
        raise UserError(f"{WORLD} {SHIFT} seed {seed}: no counterfactual, so no pair to compare")
    frames = prepare(world, task, record.rollout, record.demo)
    scenes = record.rollout.scenes[: len(frames.obs)]
    behaviour = {"moved_base": moved(world, base, scenes, d.edit)}
    behaviour["moved_tuned"] = moved(world, ad.policy, scenes, d.edit)
    shown = [k for k, c in enumerate(frames.concepts) if c.name.startswith(f"{SLOT}.")]
    if not shown:
        raise UserError(f"{WORLD} {SHIFT} seed {seed}: the test scene shows no {SLOT}")
    mask = frames.masks[shown[0]]  # (T, H, W): one object's concepts share its pixels
    rows = []
    for method in methods:
        maps = {
            who: frame_maps(policy, frames, method, seed=seed)
            for who, policy in (("base", base), ("tuned", ad.policy))
        }
        for reading in READINGS:
            s = {who: share(reading_map(*maps[who], reading), mask) for who in maps}
            rows.append(
                {
                    "seed": seed,
                    "task": task_id(task),
                    "method": method,
                    "reading": reading,
                    "share_base": round(s["base"], 6),
                    "share_tuned": round(s["tuned"], 6),
                    **{k: round(v, 6) for k, v in behaviour.items()},
                    "apart": int(s["base"] > s["tuned"] + MARGIN),
                }
            )
    return rows


def table(rows: list[dict], command: str) -> str:
    """Markdown: per method and reading, on how many seeds (where the pair differs by
    behaviour) the method gives the base policy the larger share (by MARGIN), and the mean
    shares."""
    seeds = sorted({r["seed"] for r in rows})
    tasks = len({r["task"] for r in rows})
    differ = {r["seed"] for r in rows if r["moved_base"] > r["moved_tuned"]}
    lines = [
        f"Made by `{command}`.",
        "",
        f"Seeds {seeds[0]}-{seeds[-1]} of {WORLD} {SHIFT} ({tasks} distinct test tasks: a "
        "seed's pair is finetuned on its own, so seeds stay independent units even where "
        "they share a task); the pair differs by behaviour "
        f"(removing the {SLOT} moves the base policy's actions more than the finetuned one's) "
        f"on {len(differ)} of {len(seeds)}.",
        "",
        f"| method | reading | base share > finetuned share + {MARGIN} | mean share base | "
        "mean share finetuned |",
        "|---|---|---|---|---|",
    ]
    for (method, reading), group in _grouped(rows).items():
        kept = [r for r in group if r["seed"] in differ]
        apart = sum(r["apart"] for r in kept)
        base = np.nanmean([r["share_base"] for r in kept]) if kept else float("nan")
        tuned = np.nanmean([r["share_tuned"] for r in kept]) if kept else float("nan")
        lines.append(
            f"| {method} | {reading} | {apart} of {len(kept)} seeds | {base:.3f} | {tuned:.3f} |"
        )
    return "\n".join(lines) + "\n"


def _grouped(rows: list[dict]) -> dict[tuple[str, str], list[dict]]:
    out: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        out.setdefault((r["method"], r["reading"]), []).append(r)
    return out


def write(rows: list[dict], out, command: str) -> tuple:
    """OUT/pair.csv and OUT/table.md (saying `command` made them), each written whole."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return (
        files.write_text(out / "pair.csv", buf.getvalue()),
        files.write_text(out / "table.md", table(rows, command)),
    )
