"""What `dfa export lerobot` reads: a page session, a `dfa sweep` folder or a `dfa experiment q2`
results folder, each turned into the episodes of its runs (episodes.py). Nothing is written
into the folder read from.

- session (session.jsonl): the session's events replayed as the page replays them
  (dfa_viz.app.replay.apply, the trajectories it saved read from the folder); a run per task
  loaded, each with its demonstration, variants, counterfactuals, failed and finetuned
  rollouts.
- sweep (sweep.csv): each cell's example failure (search.sweep.failure_task of its seed, edit
  and place): the policy's rollout on it (failed, dfa.edit the cell's edit) and, where the
  world has an expert that meets R' there, the expert's demonstration.
- q2 (runs.csv, config.json): each run's training data made again from its key, as the
  runner makes it: the expert's demonstration of the failing task, the variants it finetuned
  on (its condition's feedback, its budget) and the base policy's failed rollout. Finetuned
  rollouts are not made again (that is the run's finetuning).
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from dfa_viz.lerobot.episodes import edit_between, episode, run_episodes, variant_source
from policy import Policy, training_demos
from sim import get_world
from sim.core import Change, Edit, Trajectory, UserError, World
from sim.lerobot import Episode

KINDS = {"session.jsonl": "session", "sweep.csv": "sweep", "runs.csv": "q2"}


@dataclass(frozen=True)
class Source:
    """A folder to export and what it is."""

    folder: Path
    kind: str  # session, sweep or q2

    @classmethod
    def of(cls, folder: Path) -> Source:
        if not folder.is_dir():
            raise UserError(f"--from {folder}: no such folder")
        for name, kind in KINDS.items():
            if (folder / name).is_file():
                return cls(folder, kind)
        raise UserError(
            f"--from {folder}: holds none of {', '.join(KINDS)} (a page session, a dfa sweep "
            "or a dfa experiment q2 results folder)"
        )


PolicyFor = Callable[[World], Policy]


def policies(spec: str | None = None, weights: Path | None = None) -> PolicyFor:
    """The policy of each world: the base policy, or --policy/--weights (policy.outside)."""
    cache: dict[str, Policy] = {}

    def get(world: World) -> Policy:
        if world.name not in cache:
            if spec is None and weights is None:
                from policy import base_policy

                cache[world.name] = base_policy(world)
            else:
                from policy.outside import chosen_policy

                cache[world.name] = chosen_policy(world, spec, weights)
            cache[world.name].fits(world)
        return cache[world.name]

    return get


def known(world: World) -> list[Trajectory]:
    """The base policy's training demonstrations (what variants are made from besides the
    user's demonstration)."""
    return training_demos(world) if world.benchmark else []


# -- a page session ---------------------------------------------------------------------------
def session_episodes(folder: Path, policy_for: PolicyFor) -> Iterator[tuple[World, Episode]]:
    from dfa_viz.app import events as E
    from dfa_viz.app import replay as R
    from dfa_viz.app.sessions import Session, SessionError, read_events

    entries, size, _ = read_events(folder)
    session = Session(folder, entries, size, [])  # read only: not opened, not locked
    rebuild = R.Rebuild(
        policy=policy_for,
        trajectory=session.load_trajectory,
        checkpoint=lambda name, world: session.load_policy(name, world, base=policy_for(world)),
    )
    record, k = None, 0

    def done(record) -> Iterator[tuple[World, Episode]]:
        world = get_world(record.world)
        extra = known(world) if record.adaptation is not None else []
        run = f"{record.world} {record.shift} seed {record.seed} session {folder.name} task {k}"
        for ep in run_episodes(world, record, known=extra, run=run):
            yield world, ep

    for line, event in entries[1:]:
        if isinstance(event, E.TaskLoaded) and record is not None:
            yield from done(record)
            k += 1
        try:
            record = R.apply(record, event, rebuild)
        except UserError as e:
            if isinstance(e, SessionError):
                raise
            raise SessionError(f"{session.path}:{line}: {e}") from None
    if record is not None:
        yield from done(record)


# -- a dfa sweep ------------------------------------------------------------------------------
def parse_edit(text: str) -> Edit:
    """An edit as str(Edit) writes it: "slot.concept: old -> new; ..."."""
    changes = []
    for part in text.split("; "):
        try:
            key, move = part.split(": ", 1)
            slot, concept = key.split(".", 1)
            old, new = move.split(" -> ", 1)
        except ValueError:
            raise UserError(f"{text!r} is not an edit (slot.concept: old -> new; ...)") from None
        changes.append(Change(slot, concept, old, new))
    return Edit.of(*changes)


def _rows(path: Path) -> list[dict[str, str]]:
    try:
        text = path.read_text()
    except OSError as e:
        raise UserError(f"{path}: cannot read it ({e.strerror})") from None
    text = text[: text.rfind("\n") + 1]  # a line cut short is not a row
    return [r for r in csv.DictReader(io.StringIO(text, newline="")) if None not in r.values()]


def sweep_episodes(
    folder: Path, world: World, policy_for: PolicyFor
) -> Iterator[tuple[World, Episode]]:
    from search.sweep import Example, failure_task

    policy = policy_for(world)
    seen = set()
    for row in _rows(folder / "sweep.csv"):
        if row.get("kind") not in ("single", "pair") or not row.get("example_seed"):
            continue
        edit = parse_edit(row["example_edit"])
        pos = tuple(float(v) for v in row["example_pos"].split()) or None
        key = (int(row["example_seed"]), edit, pos)
        if key in seen:
            continue
        seen.add(key)
        try:
            task = failure_task(world, Example(key[0], edit, False, pos))
        except UserError as e:
            raise UserError(
                f"{folder / 'sweep.csv'}: {row['label']}: {e} (is --world right?)"
            ) from None
        run = f"{world.name} sweep seed {key[0]} {row['label']}"
        demo = world.demonstrate(task) if world.benchmark else None
        failed = world.rollout(task, policy)
        if demo is not None and demo.success:
            yield world, episode(world, demo, task, role="demonstration", run=run, edit=edit)
        else:
            demo = None
        yield world, episode(world, failed, task, role="failed", run=run, demo=demo, edit=edit)


# -- a dfa experiment q2 results folder -------------------------------------------------------
def q2_episodes(folder: Path) -> Iterator[tuple[World, Episode]]:
    from dfa_viz.configs import Finetuning
    from dfa_viz.experiment import runner as R
    from dfa_viz.loop import augmentation
    from policy import base_policy

    try:
        config = json.loads((folder / "config.json").read_text())["settings"]
        settings = R.Settings(Finetuning(**config["finetuning"]), int(config["max_size"]))
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise UserError(f"{folder / 'config.json'}: not a q2 results config ({e})") from None
    n_eval = settings.finetuning.n_eval
    for row in _rows(folder / "runs.csv"):
        spec = R.RunSpec(
            row["world"], row["shift"], row["condition"], int(row["budget"]), int(row["seed"])
        )
        world = get_world(spec.world)
        prep = R.prepare(spec.world, spec.shift, spec.seed, n_eval)
        if str(prep.task.seed) != row["task_seed"]:
            raise UserError(
                f"{folder / 'runs.csv'}: {spec.key} failed task seed {row['task_seed']}; here the "
                f"base policy fails task seed {prep.task.seed} first, so its data differ"
            )
        config = settings.config(spec.budget)
        taken = R.take_feedback(world, spec, settings)
        augmented, fb = taken.augmented, taken.feedback
        if augmented is None:
            augmented = augmentation(
                world, prep.task, prep.demo, fb, config=config, known=prep.known, seed=spec.seed
            )
        run = " ".join(str(v) for v in spec.key)
        task, demo = prep.task, prep.demo
        yield world, episode(world, demo, task, role="demonstration", run=run, feedback=fb)
        for v in augmented:
            src = variant_source(v, [demo, *prep.known])
            edit = None if src is None else edit_between(src.scenes[0], v.scenes[0])
            yield world, episode(world, v, task, role="variant", run=run, edit=edit, feedback=fb)
        failed = world.rollout(task, base_policy(world))
        yield world, episode(world, failed, task, role="failed", run=run, demo=demo, feedback=fb)
