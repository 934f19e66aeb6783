"""The `dfa` command: run the loop, train base policies, benchmark, demo."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Annotated

os.environ.setdefault("MUJOCO_GL", "egl")

import tyro

from sim.core import UserError


def run(
    world: str = "nav2d",
    shift: str = "object_ti",
    seed: int = 0,
    json_out: Annotated[bool, tyro.conf.arg(name="json")] = False,
    accuracy: float = 1.0,
    label: tuple[str, ...] = (),
    policy: Path | None = None,
    demo: Path | None = None,
    max_size: int = 2,
    out: Path = Path("recordings"),
) -> None:
    """Run the whole DFA loop once with the simulated user and report what happened.

    Rolls the base policy out on a failing test task of the chosen shift, takes a demonstration,
    searches the smallest concept edit that makes the policy follow it, takes TI/TR feedback,
    augments, finetunes and evaluates on 10 fresh tasks from the user's reward. Everything is
    recorded to OUT/<world>-<shift>-seed<seed>.rrd.

    Args:
        world: nav2d, doorkey or tabletop.
        shift: object_ti, object_tr, distractor_ti, distractor_tr or other.
        seed: selects the test task; the same seed gives the same run.
        json_out: print the report as one JSON object.
        accuracy: probability that each simulated feedback label is right.
        label: fixed answers, e.g. goal.colour=TR or distractor.presence=TI.
        policy: a checkpoint folder (model.safetensors + config.json) instead of the base policy.
        demo: a demonstration .npz (Trajectory) instead of the scripted expert's.
        max_size: the largest edit the search tries.
        out: folder for the recording.
    """
    from dfa_viz.assemble import run_once

    report = run_once(
        world,
        shift,
        seed,
        accuracy=accuracy,
        labels=label,
        policy_dir=policy,
        demo_path=demo,
        max_size=max_size,
        out=out,
        progress=not json_out,
    )
    if json_out:
        print(json.dumps(report.to_dict(), allow_nan=False))
    else:
        from dfa_viz.report import format_report

        print(format_report(report))


def train(worlds: tuple[str, ...] = ("nav2d",), seed: int = 0, retrain: bool = False) -> None:
    """Train (or load from the cache) the base policy of each world.

    Args:
        worlds: which worlds.
        seed: training seed.
        retrain: ignore the cache and train again.
    """
    from dfa_viz.assemble import train_base

    for name in worlds:
        path, rate = train_base(name, seed=seed, retrain=retrain)
        print(f"{name}: base policy at {path}; training-distribution success {rate:.0%}")


def bench(
    worlds: tuple[str, ...] = ("nav2d", "doorkey", "tabletop"),
    repeats: int = 3,
    page: bool = True,
    out: Path = Path("benchmarks") / "latest.md",
) -> None:
    """Measure every speed figure on this machine and write them to benchmarks/ as Markdown.

    Each world's search against a naive one-candidate-at-a-time loop timed in the same process,
    a whole `dfa run`, the tabletop's edit + render and search targets, per world the render
    throughput, finetuning time, recording size and one experiment run, and the web page
    (load, slider latency, finetune round trip).

    Args:
        worlds: which worlds to measure.
        repeats: timing repeats (the best is reported).
        page: also measure the web page in Chromium (a minute or two).
        out: the Markdown report.
    """
    from dfa_viz.bench import run_bench

    run_bench(worlds, repeats=repeats, page=page, out=out)


def demo(
    world: str = "nav2d",
    shift: str = "distractor_ti",
    seed: int = 0,
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None,
    host: str = "127.0.0.1",
) -> None:
    """Open the feedback page on a default scenario, the diagnosis already computed.

    The failed rollout, the expert's demonstration and the counterfactual are ready to scrub;
    mark the edited concepts TI or TR and press "Augment & finetune". Ctrl-C stops the server.

    Args:
        world: the world of the scenario.
        shift: the shift of the scenario.
        seed: the seed of the scenario.
        port: when left out, 8080 or the next free one; a port given must be free (0: any).
        host: the interface to bind; 0.0.0.0 exposes the page to the network.
    """
    from dfa_viz.app.address import serving_port

    serving_port(host, port)  # bad --host/--port: one line at once, before the heavy imports
    from dfa_viz.app import demo as demo_page

    demo_page(world, shift, seed, port=port, host=host)


def serve(
    world: str = "nav2d",
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None,
    host: str = "127.0.0.1",
    session: Path | None = None,
) -> None:
    """Serve the feedback web page: pick a task, demonstrate, diagnose, mark TI/TR, adapt.

    Binds 127.0.0.1 unless --host says otherwise; prints the URL. Every user action is appended
    to the session folder as JSON lines before the page acknowledges it; --session DIR resumes.

    Args:
        world: the world the page opens on.
        port: when left out, 8080 or the next free one; a port given must be free (0: any).
        host: the interface to bind; 0.0.0.0 exposes the page to the network.
        session: a session folder to resume (default: a new one under recordings/sessions/).
    """
    from dfa_viz.app.address import serving_port

    serving_port(host, port)  # bad --host/--port: one line at once, before the heavy imports
    from dfa_viz.app import serve as serve_app

    serve_app(world=world, port=port, host=host, session=session)


def experiment() -> None:
    """Reproduce the paper's experiments: `dfa experiment q2 --help`."""
    print("dfa experiment q2 [--worlds ...] [--shift object|distractor|both] [--budgets ...] ...")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `dfa` console script; user errors print one line and exit 2."""
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        if args[:1] == ["experiment"] and len(args) > 1:
            from dfa_viz.experiment.cli import experiment_main

            experiment_main(args[1:])
            return 0
        tyro.extras.subcommand_cli_from_dict(
            {
                "run": run,
                "train": train,
                "bench": bench,
                "demo": demo,
                "serve": serve,
                "experiment": experiment,
            },
            args=args,
            prog="dfa",
        )
    except UserError as e:
        print(f"dfa: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dfa: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
