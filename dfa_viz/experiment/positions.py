"""`dfa experiment positions`: failures in a world's continuous scene parameters found by a
random-forest surrogate against uniform sampling on the same budget (search.scene_search),
the surrogate's failures diagnosed in concepts (search.scene_diagnosis). Writes
OUT/<world>.json, then OUT/table.md and OUT/failures.png from every world's JSON in OUT."""

from __future__ import annotations

import json
import time
from pathlib import Path

from dfa_viz.checked_policy import checked_policy
from dfa_viz.experiment.positions_args import PositionsArgs
from dfa_viz.experiment.positions_table import write_summary
from sim.core import UserError, files


def check(args: PositionsArgs) -> None:
    for name, v, least in (("budget", args.budget, 1), ("seeds", args.seeds, 1)):
        if v < least:
            raise UserError(f"--{name} must be at least {least}, not {v}")
    if args.tasks < 1:
        raise UserError(f"--tasks is how many training tasks to search near, not {args.tasks}")
    if not 0 < args.spread <= 1:
        raise UserError(
            f"--spread is a share of each parameter's range, in (0, 1], not {args.spread}"
        )
    if args.diagnose < 0:
        raise UserError(f"--diagnose must not be negative, got {args.diagnose}")
    if args.max_candidates is not None and args.max_candidates < 1:
        raise UserError(f"--max-candidates must be at least 1, not {args.max_candidates}")


def command(args: PositionsArgs) -> str:
    parts = ["dfa experiment positions", f"--world {args.world}"]
    if args.policy:
        parts.append(f"--policy {args.policy}")
    parts += [
        f"--budget {args.budget}",
        f"--seeds {args.seeds}",
        f"--tasks {args.tasks}",
        f"--spread {args.spread}",
        f"--diagnose {args.diagnose}",
    ]
    if args.max_candidates is not None:
        parts.append(f"--max-candidates {args.max_candidates}")
    return " ".join(parts)


def run_positions(args: PositionsArgs) -> dict:
    """Both searches on every seed, the diagnoses, the world's JSON and the folder's table."""
    from search.scene_diagnosis import diagnose
    from search.scene_search import SEARCHES, Neighbourhoods, SceneSearch, curve, distinct
    from search.stats import t_interval
    from sim import get_world

    check(args)
    world = get_world(args.world)
    if not world.scene_parameters:
        raise UserError(f"{world.name} declares no continuous scene parameters to search")
    if not world.benchmark:
        raise UserError(f"{world.name} has no training tasks to search near")
    policy = checked_policy(world.name, args.policy)
    say = print if args.progress else (lambda *a, **k: None)
    config = SceneSearch(budget=args.budget, spread=args.spread)
    tasks = [world.train_task(s) for s in range(args.tasks)]  # type: ignore[attr-defined]
    hoods = Neighbourhoods(world, tasks, config.spread)
    runs, first = [], []
    for name, search in SEARCHES.items():
        per_seed = []
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            probes = search(world, policy.act, hoods, config, seed)
            per_seed.append(
                {
                    "seed": seed,
                    "failures": sum(p.failed for p in probes),
                    "distinct": distinct(hoods, probes),
                    "expert_failed": sum(p.expert_failed for p in probes),
                    "seconds": round(time.perf_counter() - t0, 1),
                    "curve": curve(probes),
                }
            )
            say(f"{world.name} {name} seed {seed}: {per_seed[-1]['failures']} failures")
            if name == "surrogate" and seed == 0:  # its failures, the first of each cell
                cells = {}
                for p in probes:
                    if p.failed:
                        cells.setdefault(hoods.cell(p), p)
                first = list(cells.values())
        runs.append({"name": name, "seeds": per_seed})
    for run in runs:
        for key in ("failures", "distinct"):
            per100 = [100 * s[key] / args.budget for s in run["seeds"]]
            run[key] = dict(zip(("mean", "low", "high"), t_interval(per100), strict=True))
    by = {r["name"]: r["seeds"] for r in runs}
    gain = [
        100 * (a["failures"] - b["failures"]) / args.budget
        for a, b in zip(by["surrogate"], by["uniform"], strict=True)
    ]
    diagnoses = []
    for p in first[: args.diagnose]:
        task = hoods.task(p.task, p.values)
        d = diagnose(world, policy, task, max_candidates=args.max_candidates)  # type: ignore[arg-type]
        say(f"{world.name} failure {p.values}: {d.summary()}")
        diagnoses.append(
            {"task": tasks[p.task].seed, "values": p.to_dict()["values"], **d.to_dict()}
        )
    record = {
        "world": world.name,
        "policy": args.policy or "base policy",
        "command": command(args),
        "parameters": [p.to_dict() for p in world.scene_parameters],
        "tasks": args.tasks,
        "budget": args.budget,
        "spread": args.spread,
        "runs": runs,
        "gain": dict(zip(("mean", "low", "high"), t_interval(gain), strict=True)),
        "diagnoses": diagnoses,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    files.write_text(out / f"{files.safe_name(world.name)}.json", json.dumps(record) + "\n")
    write_summary(out)
    return record
