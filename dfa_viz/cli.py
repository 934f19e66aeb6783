"""The `dfa` command: one subcommand per frozen *Args config (the core's in dfa_viz.configs,
each client's in its args.py), parsed by tyro.

    dfa run | train | worlds | check-world | bench | prior | demo | serve | sweep | experiment q2
    dfa export lerobot | view
    dfa experiment explain | search | unplanted | positions
    dfa study new | study serve | study analyse

Each subcommand's help is its config's docstring and fields; a UserError (bad input) prints
one line and exits 2; a disk that fills up (or a quota, or a file size limit) prints one line
naming the file and exits 1, leaving what was written whole, so that the same command run
again with room resumes or starts afresh.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from pathlib import Path
from typing import Annotated, Union

os.environ.setdefault("MUJOCO_GL", "egl")

import tyro

from dfa_viz.app.args import DemoArgs, ServeArgs
from dfa_viz.bench.args import BenchArgs
from dfa_viz.configs import (
    AdaptConfig,
    CheckWorldArgs,
    PriorArgs,
    RunArgs,
    TrainArgs,
    WorldsArgs,
)
from dfa_viz.experiment.args import ExplainArgs, PairArgs, Q2Args, UnplantedArgs
from dfa_viz.experiment.positions_args import PositionsArgs
from dfa_viz.lerobot.args import ExportArgs, ViewArgs
from dfa_viz.study.args import AnalyseStudyArgs, NewStudyArgs, ServeStudyArgs
from dfa_viz.sweep.args import SearchArgs, SweepArgs
from sim.core import UserError, files

Experiment = Union[  # noqa: UP007 (the experiments, subcommands of `dfa experiment`)
    Annotated[Q2Args, tyro.conf.subcommand("q2")],
    Annotated[ExplainArgs, tyro.conf.subcommand("explain")],
    Annotated[PairArgs, tyro.conf.subcommand("pair")],
    Annotated[SearchArgs, tyro.conf.subcommand("search")],
    Annotated[PositionsArgs, tyro.conf.subcommand("positions")],
    Annotated[UnplantedArgs, tyro.conf.subcommand("unplanted")],
]
Study = Union[  # noqa: UP007 (the study's subcommands, `dfa study new|serve|analyse`)
    Annotated[NewStudyArgs, tyro.conf.subcommand("new")],
    Annotated[ServeStudyArgs, tyro.conf.subcommand("serve")],
    Annotated[AnalyseStudyArgs, tyro.conf.subcommand("analyse")],
]
Command = Union[  # noqa: UP007 (tyro reads the union's members as subcommands)
    Annotated[RunArgs, tyro.conf.subcommand("run")],
    Annotated[TrainArgs, tyro.conf.subcommand("train")],
    Annotated[WorldsArgs, tyro.conf.subcommand("worlds")],
    Annotated[CheckWorldArgs, tyro.conf.subcommand("check-world")],
    Annotated[BenchArgs, tyro.conf.subcommand("bench")],
    Annotated[PriorArgs, tyro.conf.subcommand("prior")],
    Annotated[DemoArgs, tyro.conf.subcommand("demo")],
    Annotated[ServeArgs, tyro.conf.subcommand("serve")],
    Annotated[SweepArgs, tyro.conf.subcommand("sweep")],
    Annotated[ExportArgs, tyro.conf.subcommand("export")],
    Annotated[ViewArgs, tyro.conf.subcommand("view")],
    Annotated[
        Experiment,
        tyro.conf.subcommand(
            "experiment",
            description="Run one of the experiments: q2 (finetuning), explain, pair (can an "
            "explainer tell a policy thrown by a distractor or an object's new look from one "
            "taught to ignore it), or "
            "search (how fast other searches find the sweep's failure modes), or unplanted "
            "(the search, saliency and the learned prior on failures nobody planted), or "
            "positions (failures in continuous scene parameters, diagnosed in concepts).",
        ),
    ],
    Annotated[
        Study,
        tyro.conf.subcommand(
            "study",
            description="The paper's user study: new (freeze the tasks), serve (the page for "
            "participants), analyse (accuracy and tests).",
        ),
    ],
]


def run(args: RunArgs) -> None:
    from dfa_viz.assemble import run_once

    record = run_once(args, progress=not args.json)
    if args.json:
        print(json.dumps(record.to_json(), allow_nan=False))
    else:
        from dfa_viz.report import format_report

        print(format_report(record))


def train(args: TrainArgs) -> None:
    from dfa_viz.assemble import train_base

    for name in args.worlds:
        path, rate = train_base(name, seed=args.seed, retrain=args.retrain)
        print(f"{name}: base policy at {path}; success on its training tasks {rate:.0%}")


def worlds(args: WorldsArgs) -> None:
    from sim import get_world, world_names

    for name in args.names or tuple(n for n in world_names() if not n.endswith(":...")):
        world = get_world(name)
        print(f"{name}: {describe(world)}")
    if not args.names:
        print("minigrid:<EnvId>[:tile=N][:view=partial]: any registered MiniGrid environment")


def describe(world) -> str:
    """A world in one line: its slots and concepts, actions, horizon and capabilities."""
    slots = []
    for s in world.space.slots:
        names = [f"{c.name}({len(c.values)})" for c in s.concepts]
        names = (["presence"] if s.optional else []) + names
        slots.append(f"{s.name}[{', '.join(names)}]")
    acts = f"{world.action_dim} discrete" if world.discrete else f"{world.action_dim}-d continuous"
    kind = "shifts " + "/".join(world.shifts) if world.shifts else "diagnosis from a demonstration"
    steps = "1 step" if world.horizon == 1 else f"up to {world.horizon} steps"
    demo = {"pick_place": "pick and place", "effector": "clicked gripper waypoints"}.get(
        world.demo_input, world.demo_input
    )
    return (
        f"{' '.join(slots)}; frames {world.obs_shape[0]}x{world.obs_shape[1]}, {acts} actions, "
        f"{steps}; demonstrations by {demo}; {kind}"
    )


def check_world(args: CheckWorldArgs) -> int:
    from sim import get_world
    from sim.contract import check_world as run_contract

    world = get_world(args.name)
    results = run_contract(world)
    for r in results:
        print(f"{'PASS' if r.passed else 'FAIL'}  {r.name}{'' if r.passed else f': {r.message}'}")
    held = sum(r.passed for r in results)
    print(f"{world.name}: {held} of {len(results)} parts of the world contract hold")
    return 0 if held == len(results) else 1


def bench(args: BenchArgs) -> None:
    from dfa_viz.bench.run import run_bench

    run_bench(args)


def prior(args: PriorArgs) -> None:
    from dfa_viz.assemble import fit_prior

    learned, seeds = fit_prior(args)
    print(
        f"learned prior for {learned.world} fitted on {args.tasks} planted tasks "
        f"({seeds} seeds tried), written to {args.out}"
    )


def demo(args: DemoArgs) -> None:
    from dfa_viz.app.address import serving_port

    serving_port(
        args.host, args.port
    )  # bad --host/--port: one line at once, before the heavy imports
    from dfa_viz.app.server import demo as demo_page

    demo_page(args)


def serve(args: ServeArgs) -> None:
    from dfa_viz.app.address import serving_port

    serving_port(args.host, args.port)  # as for demo
    from dfa_viz.app.server import serve as serve_page

    serve_page(args)


def experiment(args: Q2Args) -> None:
    from dfa_viz.experiment.cli import experiment_q2

    experiment_q2(args)


def explain(args: ExplainArgs) -> None:
    from dfa_viz.experiment.cli import experiment_explain

    experiment_explain(args)


def pair(args: PairArgs) -> None:
    from dfa_viz.experiment.cli import experiment_pair

    experiment_pair(args)


def unplanted(args: UnplantedArgs) -> None:
    from dfa_viz.experiment.cli import experiment_unplanted

    experiment_unplanted(args)


def search(args: SearchArgs) -> None:
    from dfa_viz.sweep.compare import run_search_comparison

    record = run_search_comparison(args)
    print(f"{record['world']}: {len(record['modes'])} failure modes; {args.out}/table.md")


def positions(args: PositionsArgs) -> None:
    from dfa_viz.experiment.positions import run_positions

    record = run_positions(args)
    gain = record["gain"]
    print(
        f"{record['world']}: the surrogate finds {gain['mean']:+.1f} failures per 100 rollouts "
        f"against uniform sampling ({gain['low']:+.1f} to {gain['high']:+.1f}); "
        f"{args.out}/table.md"
    )


def sweep(args: SweepArgs) -> None:
    from dfa_viz.sweep.run import run_sweep
    from dfa_viz.sweep.tables import summary, tables

    out = run_sweep(args)
    from rich.console import Console

    console = Console()
    if not console.is_terminal:
        console = Console(width=120)
    for table in tables(out.result):
        console.print(table)
    console.print(summary(out.result, out.wall_s))
    for path in (out.csv, out.heatmap, out.recording):
        console.print(f"  {path}", highlight=False)


def export(args: ExportArgs) -> None:
    from dfa_viz.lerobot.export import export as export_dataset

    print(export_dataset(args).summary())


def view(args: ViewArgs) -> None:
    from dfa_viz.lerobot.view import write_view

    out = args.out or Path("recordings") / files.safe_name(f"{args.dataset.resolve().name}.rrd")
    viewed = write_view(args.dataset, out, episodes=args.episodes, camera=args.camera)
    print(f"{viewed.path}: {viewed.episodes} episodes, {viewed.frames} frames; open it with rerun")


def study(args) -> None:
    from dfa_viz.study import cli as study_cli

    {
        NewStudyArgs: study_cli.study_new,
        ServeStudyArgs: study_cli.study_serve,
        AnalyseStudyArgs: study_cli.study_analyse,
    }[type(args)](args)


HANDLERS = {
    RunArgs: run,
    TrainArgs: train,
    WorldsArgs: worlds,
    CheckWorldArgs: check_world,
    BenchArgs: bench,
    PriorArgs: prior,
    DemoArgs: demo,
    ServeArgs: serve,
    Q2Args: experiment,
    ExplainArgs: explain,
    PairArgs: pair,
    SearchArgs: search,
    PositionsArgs: positions,
    UnplantedArgs: unplanted,
    SweepArgs: sweep,
    ExportArgs: export,
    ViewArgs: view,
    NewStudyArgs: study,
    ServeStudyArgs: study,
    AnalyseStudyArgs: study,
}


# their --out names a file; every other --out, a folder
OUTPUT_FILES = (BenchArgs, PriorArgs, ViewArgs)


def check_output(config) -> None:
    """Refuse, before any work, an --out that cannot be written: a folder given where a file
    goes or the other way round, a file on the way to it, a folder that cannot be written to."""
    if "out" not in {f.name for f in dataclasses.fields(config)} or config.out is None:
        return
    out = Path(config.out)
    folder = not isinstance(config, OUTPUT_FILES)
    if folder and out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is a file; give a folder for the outputs")
    if not folder and out.is_dir():
        raise UserError(f"--out {out} is a folder; give the name of the file to write")
    above = out.parent if not folder or not out.exists() else out
    while not above.exists():
        above = above.parent
    if not above.is_dir():
        raise UserError(f"--out {out}: {above} is a file, so nothing can be written under it")
    if not os.access(above, os.W_OK | os.X_OK):
        raise UserError(f"--out {out}: {above} cannot be written to")


def no_space(e: OSError) -> str:
    """A write that ran out of room, in one line."""
    where = f"{e.filename}: " if e.filename else ""
    return f"{where}no space left to write it ({e.strerror}); make room and run the command again"


def named_world(args: list[str]) -> str | None:
    """The value of the last --world among `args`, or None."""
    name = None
    for i, arg in enumerate(args):
        if arg == "--world" and i + 1 < len(args):
            name = args[i + 1]
        elif arg.startswith("--world="):
            name = arg.partition("=")[2]
    return name


def parse(args: list[str]):
    """The config `dfa ARGS` asks for. `dfa run --world W` starts from W's finetuning settings
    (AdaptConfig.for_world), which its --help shows and the options given override."""
    if args[:1] == ["run"] and (name := named_world(args[1:])) is not None:
        from sim import get_world

        adapt = AdaptConfig.for_world(get_world(name))
        if adapt != AdaptConfig():
            default = RunArgs(world=name, adapt=adapt)
            return tyro.cli(RunArgs, args=args[1:], prog="dfa run", default=default)
    return tyro.cli(Command, args=args, prog="dfa", config=(tyro.conf.OmitSubcommandPrefixes,))


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `dfa` console script; user errors print one line and exit 2, a full
    disk one line and exit 1."""
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        config = parse(args)
        check_output(config)
        status = HANDLERS[type(config)](config)  # an int where the command says how it went
    except UserError as e:
        print(f"dfa: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        if e.errno not in files.NO_SPACE:
            raise
        print(f"dfa: error: {no_space(e)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("dfa: interrupted", file=sys.stderr)
        return 130
    return status or 0


if __name__ == "__main__":
    sys.exit(main())
