"""`dfa experiment pair`: the explainer benchmark's model pair. Two policies of one architecture
that differ in one thing an explainer should see: a world's base policy, cloned on a look that
makes a concept spurious, is thrown when the concept changes (its failing test task of a TI
shift); the same policy after the loop's TI feedback (variants over the concept's accepted
values, finetuned) is not. One row group per (world, shift): nav2d's and DoorKey's new
distractor (distractor_ti: the distractor's, or the lava's, presence) and recoloured or
reshaped object (object_ti: the goal's, key's or door's look).

The ground truth is behaviour, per seed: on the failed rollout's scenes, undoing the cause (the
changes of the counterfactual's edit to the cause's concept, `undo`) moves the base policy's
actions by `moved_base` and the finetuned one's by `moved_tuned`; the pair differs where
moved_base > moved_tuned (nan, and no verdict, where the edit leaves the cause alone). On the
same frames, each saliency method's share of its attribution inside the cause's pixels (by
magnitude, and of the blame: the attribution pushing the action away from the demonstration)
is read for both policies; an explainer tells the pair apart on a seed when it gives the base
policy the larger share, by at least MARGIN. Seeds are independent units (each pair is
finetuned on its own, even where two seeds draw one task); a table counts them per group,
method and reading, beside the group's distinct test tasks.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence

import numpy as np

from dfa_viz.configs import AdaptConfig
from policy.methods import METHOD_NAMES
from sim import PAPER_WORLDS, get_world
from sim.core import Edit, UserError, files

PAIR_SHIFTS = ("distractor_ti", "object_ti")
"""The shifts a pair is made for: those whose feedback teaches the policy to ignore the cause."""
MARGIN = 0.01  # shares closer than this (a point of the attribution) are a tie, not a verdict
COLUMNS = (
    "world",
    "shift",
    "seed",
    "task",
    "cause",
    "undo",
    "method",
    "reading",
    "share_base",
    "share_tuned",
    "moved_base",
    "moved_tuned",
    "apart",
)


def pair_worlds() -> tuple[str, ...]:
    """The worlds a pair is made in: the paper's worlds whose rollouts are not a physics
    simulation (World.simulated), where the loop takes seconds a seed (the tabletop's physics
    rollouts are left out for their cost)."""
    return tuple(name for name in PAPER_WORLDS if not get_world(name).simulated)


def check_pair(worlds: Sequence[str], shifts: Sequence[str], seeds: int) -> None:
    """Raise a one-line UserError for a world, shift or seed count a pair cannot be made for."""
    if seeds < 1:
        raise UserError(f"--seeds is how many seeds to run, at least 1, not {seeds}")
    for option, given, accepted in (
        ("--world", worlds, pair_worlds()),
        ("--shift", shifts, PAIR_SHIFTS),
    ):
        bad = [g for g in given if g not in accepted] or ([] if given else ["(none)"])
        if bad:
            raise UserError(f"{option} {bad[0]!r}: accepted: {', '.join(accepted)}")


def moved(world, policy, scenes: Sequence, edit) -> float:
    """Mean L1 distance between the policy's actions on the scenes and on them edited; in a
    discrete world, between its action probabilities (the softmax of its scores: 0 .. 2)."""
    a = _actions(world, policy, list(scenes))  # (T, A)
    b = _actions(world, policy, [world.apply(s, edit) for s in scenes])  # (T, A)
    return float(np.abs(a - b).sum(axis=1).mean())


def _actions(world, policy, scenes: list) -> np.ndarray:
    obs = world.render_batch(scenes)
    if not world.discrete:
        return policy.act(obs)  # float32 (T, A)
    scores = policy.outputs(obs).astype(np.float64)  # (T, A) logits
    e = np.exp(scores - scores.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def share(maps: np.ndarray, mask: np.ndarray) -> float:
    """The positive part of `maps` (T, H, W) inside `mask` (T, H, W) over all of it."""
    m = np.clip(maps.astype(np.float64), 0.0, None)
    total = m.sum()
    return float(m[mask].sum() / total) if total > 0 else float("nan")


def undo_of(space, cause: tuple[str, str], edit: Edit) -> Edit | None:
    """The changes of `edit` to the cause's concept (every slot of its kind: "lava.presence"
    covers each lava tile), None when it changes none."""
    members = set(space.user_concept(*cause).members)
    kept = [c for c in edit.changes if (c.slot, c.concept) in members]
    return Edit.of(*kept) if kept else None


def pair_rows(
    seed: int,
    *,
    world_name: str = "nav2d",
    shift: str = "distractor_ti",
    config: AdaptConfig = AdaptConfig(),
    methods: Sequence[str] = METHOD_NAMES,
) -> list[dict]:
    """One seed of one (world, shift): the pair made by the loop, its behaviour and each
    method's shares."""
    from dfa_viz.experiment.explain import task_id
    from dfa_viz.loop import run_loop
    from dfa_viz.users import SimulatedUser
    from policy import base_policy, failing_test_task
    from policy.concept_saliency import READINGS, frame_maps, prepare, reading_map
    from sim import get_world

    check_pair((world_name,), (shift,), 1)
    world = get_world(world_name)
    base = base_policy(world)
    task, _ = failing_test_task(world, base, shift, seed)
    assert task.cause is not None, f"{shift} tasks have no planted cause"
    record = run_loop(world, base, task, SimulatedUser(world, seed=seed), seed=seed, config=config)
    d, ad = record.diagnosis, record.adaptation
    where = f"{world_name} {shift} seed {seed}"
    if d is None or d.edit is None or ad is None or ad.policy is None:
        raise UserError(f"{where}: no counterfactual, so no pair to compare")
    cause = world.space.user_concept(*task.cause).name
    frames = prepare(world, task, record.rollout, record.demo)
    names = [c.name for c in frames.concepts]
    if cause not in names:
        raise UserError(f"{where}: the test scene does not show its cause {cause}")
    mask = frames.masks[names.index(cause)]  # (T, H, W): the pixels of the cause's objects
    scenes = record.rollout.scenes[: len(frames.obs)]
    undo = undo_of(world.space, task.cause, d.edit)
    behaviour = {
        who: moved(world, policy, scenes, undo) if undo is not None else float("nan")
        for who, policy in (("moved_base", base), ("moved_tuned", ad.policy))
    }
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
                    "world": world_name,
                    "shift": shift,
                    "seed": seed,
                    "task": task_id(task),
                    "cause": cause,
                    "undo": str(undo) if undo is not None else "-",
                    "method": method,
                    "reading": reading,
                    "share_base": round(s["base"], 6),
                    "share_tuned": round(s["tuned"], 6),
                    **{k: round(v, 6) for k, v in behaviour.items()},
                    "apart": int(s["base"] > s["tuned"] + MARGIN),
                }
            )
    return rows


def differs(row: dict) -> bool:
    """Whether the seed's pair differs by behaviour (False where the cause was not undone)."""
    base, tuned = float(row["moved_base"]), float(row["moved_tuned"])
    return not math.isnan(base) and base > tuned


def table(rows: list[dict], command: str) -> str:
    """Markdown: per (world, shift) its seeds, distinct tasks and per-seed behaviour check, and
    per method and reading on how many seeds (where the pair differs by behaviour) the method
    gives the base policy the larger share (by MARGIN), with the mean shares."""
    groups = _grouped(rows, ("world", "shift"))
    lines = [
        f"Made by `{command}`.",
        "",
        "Per world and shift, seeds 0 .. N-1, each the base policy's first failing test task of "
        "the seed and the loop's TI-finetuned copy of that policy (a seed's pair is finetuned on "
        "its own, so seeds stay independent units even where they share a task: the distinct "
        "tasks are counted beside them). Behaviour, the ground truth: the changes of the "
        "counterfactual's edit to the cause's concept undone on the failed rollout's frames "
        "move the base policy's actions (L1 in nav2d; in DoorKey, L1 between the action "
        "probabilities, 0 .. 2) more than the finetuned one's. A method tells the pair apart "
        "on a seed when it gives the base policy a share of its attribution on the cause's "
        f"pixels larger by more than {MARGIN}, by magnitude (abs) or of the blame (signed); "
        "counted over the seeds whose pair differs by behaviour.",
        "",
        "## Behaviour, per seed",
        "",
        "| world | shift | seed | task | cause undone | moved base | moved finetuned | differs |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (world, shift), group in groups.items():
        for seed, first in _grouped(group, ("seed",)).items():
            r = first[0]
            lines.append(
                f"| {world} | {shift} | {seed[0]} | {r['task']} | {r['undo']} | "
                f"{_num(r['moved_base'])} | {_num(r['moved_tuned'])} | "
                f"{'yes' if differs(r) else 'no'} |"
            )
    lines += [
        "",
        "## Can each method tell the pair apart?",
        "",
        f"| world | shift | seeds (distinct tasks) | differ by behaviour | method | reading | "
        f"base share > finetuned share + {MARGIN} | mean share base | mean share finetuned |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (world, shift), group in groups.items():
        seeds = {int(r["seed"]) for r in group}
        tasks = len({r["task"] for r in group})
        differ = {int(r["seed"]) for r in group if differs(r)}
        head = f"| {world} | {shift} | {len(seeds)} ({tasks}) | {len(differ)} of {len(seeds)} |"
        for (method, reading), cell in _grouped(group, ("method", "reading")).items():
            kept = [r for r in cell if int(r["seed"]) in differ]
            apart = sum(int(r["apart"]) for r in kept)
            base = _mean([r["share_base"] for r in kept])
            tuned = _mean([r["share_tuned"] for r in kept])
            lines.append(
                f"{head} {method} | {reading} | {apart} of {len(kept)} seeds | "
                f"{_num(base)} | {_num(tuned)} |"
            )
    return "\n".join(lines) + "\n"


def _mean(values: list) -> float:
    kept = [float(v) for v in values if not math.isnan(float(v))]
    return float(np.mean(kept)) if kept else float("nan")


def _num(x) -> str:
    x = float(x)
    return "-" if math.isnan(x) else f"{x:.3f}"


def _grouped(rows: list[dict], keys: tuple[str, ...]) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
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
