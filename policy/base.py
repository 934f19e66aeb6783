"""The base policies of record: one per world, committed under policy/weights/<world>/.

A base policy is cloned on the expert's demonstrations of the world's training distribution.
Cloning on a CPU gives other weights on another processor (torch's kernels differ between
Intel and AMD), so the weights every result and test is measured with are committed to the
repository, with the recipe they were trained from in their config.json:

    recipe      the training settings, the architecture, a hash of the training tasks' initial
                scenes and of the demonstrated actions (rounded, so that no float-level detail
                of a processor enters it), and per demonstration the mean colour of its frames
    command     the command that trained them (`dfa train --retrain --worlds <world>`)
    trained_on  the machine, torch's version, the date, the final loss, the training success

`base_policy(world)` loads the committed weights once it has checked that today's recipe is the
one they were trained with (every training task's expert run, the frames of a few of them:
`checked_recipe`). A changed recipe with stale weights is an error that names the
command to retrain, never a silent retrain. Worlds without committed weights (and seeds other
than 0) are trained on first use and cached under `files.cache_dir()` instead.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policy.checkpoint import load_policy, read_config, save_policy
from policy.model import Policy
from policy.train import (
    LossCallback,
    TrainConfig,
    base_arch,
    base_config,
    clone_base,
    training_demos,
    training_tasks,
)
from sim.core import Trajectory, UserError, World, files

WEIGHTS = Path(__file__).parent / "weights"
RECORD_SEED = 0  # the seed whose base policies are committed
FRAME_TOLERANCE = 0.5  # mean frame colours may differ this much (of 255) between renderers
FRAMES_CHECKED = 10  # training demonstrations drawn to check a committed policy's frames


def machine_name() -> str:
    """The processor and core count, as one line (e.g. "Intel(R) Xeon(R) Processor; 2 logical
    cores")."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}; {os.cpu_count()} logical cores"


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def recipe(world: World, demos: list[Trajectory], *, seed: int, config: TrainConfig) -> dict:
    """What a base policy is trained from, in terms that are the same on every processor."""
    colours = [_mean_colour(d.observations) for d in demos]
    runs = [(list(d.scenes), d.actions) for d in demos]
    return _recipe(world, runs, colours, seed=seed, config=config)


def checked_recipe(world: World, *, seed: int, config: TrainConfig) -> dict:
    """Today's recipe as a committed policy's is checked against, without drawing every
    training demonstration: each training task's expert run (its scenes and actions, the
    physics alone) and the frames of FRAMES_CHECKED runs spread over them; the others' frame
    colours are None and not compared (a changed renderer or camera changes every run's
    frames). A 200-demonstration MuJoCo world is checked in seconds instead of minutes."""
    tasks = training_tasks(world, seed)
    noise = world.cloning.noise
    runs = [world.expert_run(t, noise=noise, seed=t.seed) for t in tasks]
    drawn = set(np.linspace(0, len(runs) - 1, min(len(runs), FRAMES_CHECKED)).round().astype(int))
    colours = [
        _mean_colour(world.render_batch(scenes)) if i in drawn else None
        for i, (scenes, _) in enumerate(runs)
    ]
    return _recipe(world, runs, colours, seed=seed, config=config)


def _mean_colour(frames: np.ndarray) -> list[float]:
    """The mean RGB of uint8 frames (T, H, W, 3), rounded."""
    return [round(float(c), 3) for c in frames.reshape(-1, 3).mean(axis=0)]


def _recipe(world: World, runs: list, colours: list, *, seed: int, config: TrainConfig) -> dict:
    """runs: each demonstration's (scenes, actions); colours: each one's mean frame colour."""
    arch = base_arch(world)
    actions = [np.round(np.asarray(a, np.float64), 4).tolist() for _, a in runs]
    doc = {
        "world": world.name,
        "seed": seed,
        "train": config.to_dict(),
        "policy": arch.to_dict(),
        "demonstrations": len(runs),
        "initial_scenes": _sha(json.dumps([scenes[0].to_dict() for scenes, _ in runs])),
        "actions": _sha(json.dumps(actions)),
        "frame_colours": colours,
    }
    if world.cloning.dagger_rounds:  # only where asked: the other worlds' recipes stay as they were
        doc["dagger_rounds"] = world.cloning.dagger_rounds
    return json.loads(json.dumps(doc))  # as it reads back from config.json (lists, not tuples)


def recipe_change(then: dict, now: dict) -> str | None:
    """How two recipes differ (None when they agree): the first differing part, in words."""
    for key in sorted(set(then) | set(now)):
        a, b = then.get(key), now.get(key)
        if key == "frame_colours" and isinstance(a, list) and isinstance(b, list):
            same = len(a) == len(b) and all(
                y is None or np.abs(np.subtract(x, y)).max() <= FRAME_TOLERANCE
                for x, y in zip(a, b, strict=True)
            )
            if not same:
                return (
                    "the training frames look different "
                    "(the renderer, the tasks or the cached views changed)"
                )
        elif isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if a.get(k) != b.get(k):
                    return f"{key}.{k}: {json.dumps(a.get(k))} then, {json.dumps(b.get(k))} now"
        elif a != b:
            return f"{key}: {json.dumps(a)[:40]} then, {json.dumps(b)[:40]} now"
    return None


def base_folder(
    world: World, *, seed: int = RECORD_SEED, config: TrainConfig | None = None
) -> Path:
    """Where a world's base policy is kept: policy/weights/<world>/ for the policies of record
    (seed 0, the default recipe), else a cache folder named by the recipe."""
    config = config or base_config(world)
    if of_record(world, seed, config):
        return record_folder(world)
    now = recipe(world, training_demos(world, seed), seed=seed, config=config)
    return _cached(now)


def record_folder(world: World) -> Path:
    """policy/weights/<world>/, the world's name made a file name ("fetch:FetchPush-v4" ->
    "fetch_FetchPush-v4")."""
    return WEIGHTS / files.safe_name(world.name)


def of_record(world: World, seed: int, config: TrainConfig) -> bool:
    """True for the policies of record: seed 0 and the default recipe of a world whose weights
    are committed (other worlds, e.g. any MiniGrid environment, are cached outside the
    repository)."""
    return seed == RECORD_SEED and config == base_config(world) and record_folder(world).is_dir()


def base_policy(
    world: World,
    *,
    seed: int = RECORD_SEED,
    config: TrainConfig | None = None,
    retrain: bool = False,
    on_loss: LossCallback | None = None,
) -> Policy:
    """The base policy of `world`: the committed weights of record, checked against today's
    recipe; trained (and cached) where none are committed. `retrain` trains it again and
    writes it where it is kept (policy/weights/<world>/ for the policies of record).
    `config`: the cloning settings (default: the world's, policy.train.base_config)."""
    config = config or base_config(world)
    record = of_record(world, seed, config)
    if record and not retrain and (record_folder(world) / "config.json").is_file():
        folder = record_folder(world)
        then = read_config(folder).get("meta", {}).get("recipe", {})
        change = recipe_change(then, checked_recipe(world, seed=seed, config=config))
        if change is not None:
            first = ""
            if change.startswith("the training frames look different"):
                first = (
                    "if they were drawn from damaged cached views, delete the cache "
                    f"{files.cache_dir()} ($DFA_CACHE, else ~/.cache/dfa) and run again; "
                    "if they still differ, "
                )
            raise UserError(
                f"the committed {world.name} base policy ({folder}) was trained with another "
                f"recipe ({change}); {first}retrain the policy with `dfa train --retrain "
                f"--worlds {world.name}` and commit {folder}"
            )
        return load_policy(folder, world=world)
    demos = training_demos(world, seed)
    now = recipe(world, demos, seed=seed, config=config)
    folder = record_folder(world) if record else _cached(now)
    if not retrain and (folder / "model.safetensors").is_file():
        try:
            return load_policy(folder, world=world)
        except UserError as e:  # a damaged cache entry is dropped and made again
            print(
                f"dfa: the cached base policy is unusable ({e}); training it again", file=sys.stderr
            )
    policy, losses = clone_base(world, demos, seed=seed, config=config, on_loss=on_loss)
    solved = sum(r.success for r in world.rollout_batch(training_tasks(world, seed), policy))
    meta: dict[str, Any] = {
        "recipe": now,
        "command": f"dfa train --retrain --worlds {world.name}"
        + (f" --seed {seed}" if seed else ""),
        "trained_on": machine_name(),
        "torch": torch.__version__,
        "date": time.strftime("%Y-%m-%d"),
        "final_loss": round(losses[-1], 6),
        "training_tasks_solved": f"{solved}/{len(demos)}",
    }
    save_policy(policy, folder, meta=meta)
    return policy


def _cached(now: dict) -> Path:
    key = _sha(json.dumps({k: v for k, v in now.items() if k != "frame_colours"}, sort_keys=True))
    return files.cache_dir() / "policies" / files.safe_name(f"{now['world']}-{key}")
