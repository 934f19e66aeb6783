"""`dfa experiment q2` (the paper's finetuning comparison) and `dfa experiment explain` (the
explanations against the planted causes): one config each, shared by the CLI and the function
it runs."""

from __future__ import annotations

from dfa_viz.experiment.args import ExplainArgs, PairArgs, Q2Args, UnplantedArgs


def experiment_q2(args: Q2Args) -> None:
    """Plan, run (skipping finished runs) and report the comparison."""
    from dfa_viz.experiment.conditions import SHIFT_KINDS
    from dfa_viz.experiment.experiment import Plan, run_experiment
    from dfa_viz.experiment.runner import Settings
    from sim.core import UserError

    if args.seeds < 1:
        raise UserError(f"--seeds is how many seeds to run, at least 1, not {args.seeds}")
    if args.max_size < 1:
        raise UserError(f"--max-size must be at least 1, not {args.max_size}")
    args.finetuning.check()
    if args.finetuning.replay_looks == "painted":  # each world's one line, before any run
        from sim import get_world

        for name in dict.fromkeys(args.worlds):
            args.finetuning.check(get_world(name))
    plan = Plan(
        worlds=tuple(dict.fromkeys(args.worlds)),
        shifts=SHIFT_KINDS if args.shift == "both" else (args.shift,),
        conditions=tuple(dict.fromkeys(args.conditions)),
        budgets=tuple(sorted(set(args.budgets))),
        seeds=tuple(range(args.seeds)),
    )
    summary = run_experiment(
        plan,
        out=args.out,
        settings=Settings(args.finetuning, args.max_size, args.baseline_h),
        backend=args.backend,
        workers=args.workers,
        ray_address=args.ray_address,
        progress=args.progress,
    )
    _report(summary, items="runs", done="run")


def experiment_explain(args: ExplainArgs) -> None:
    """Plan, run (skipping finished tasks) and report the explanation benchmark."""
    from dfa_viz.experiment.explain import ExplainSettings
    from dfa_viz.experiment.explain_run import ExplainPlan, run_explain

    summary = run_explain(
        ExplainPlan(tuple(args.worlds), tuple(args.shifts), args.tasks),
        out=args.out,
        settings=ExplainSettings(tuple(dict.fromkeys(args.methods)), args.max_size),
        backend=args.backend,
        workers=args.workers,
        ray_address=args.ray_address,
        progress=args.progress,
    )
    _report(summary, items="tasks", done="explained")


def experiment_pair(args: PairArgs) -> None:
    """Make and compare the model pair of each world, shift and seed; write the rows and the
    table."""
    from tqdm import tqdm

    from dfa_viz.experiment.model_pair import check_pair, pair_rows, pair_worlds, write

    worlds = tuple(dict.fromkeys(args.worlds)) or pair_worlds()
    shifts = tuple(dict.fromkeys(args.shifts))
    check_pair(worlds, shifts, args.seeds)
    jobs = [(w, s, seed) for w in worlds for s in shifts for seed in range(args.seeds)]
    rows = [
        r
        for w, s, seed in tqdm(jobs, desc="pairs", unit="seed")
        for r in pair_rows(seed, world_name=w, shift=s)
    ]
    command = (
        f"dfa experiment pair --world {' '.join(worlds)} --shift {' '.join(shifts)} "
        f"--seeds {args.seeds} --out {args.out}"
    )
    for path in write(rows, args.out, command):
        print(f"  {path}")


def experiment_unplanted(args: UnplantedArgs) -> None:
    """Draw, measure and table one world's unplanted failures."""
    import time

    from tqdm import tqdm

    from dfa_viz.experiment.unplanted import OTHERS, TASK_COLUMNS, run_world
    from dfa_viz.experiment.unplanted_table import merge, read_csv
    from policy.outside import chosen_policy
    from search.prior import LearnedPrior
    from search.unplanted import check_kind
    from sim import check_world_name, get_world
    from sim.core import UserError, check_seed

    check_seed(args.seed)
    if args.tasks < 1:
        raise UserError(f"--tasks must be at least 1, not {args.tasks}")
    if args.prior_tasks < 0:
        raise UserError(f"--prior-tasks must be 0 (no prior) or more, not {args.prior_tasks}")
    if args.tries < args.tasks:
        raise UserError(f"--tries {args.tries} is fewer than --tasks {args.tasks}")
    if args.out.exists() and not args.out.is_dir():
        raise UserError(f"--out {args.out} is a file; give a folder")
    read_csv(args.out / "tasks.csv", TASK_COLUMNS)  # an older folder: one line, before the work
    world = get_world(check_world_name(args.world))
    check_kind(world, args.kind)
    if not world.benchmark:
        raise UserError(f"{world.name} has no training tasks or expert to judge failures by")
    policy = chosen_policy(world, args.policy)
    t0 = time.perf_counter()
    if args.prior_fit == "others":
        if args.prior is not None or args.tasks < 2:
            raise UserError("--prior-fit others fits on the run's other tasks: give no --prior "
                            "and --tasks 2 or more")  # fmt: skip
        prior, prior_text = OTHERS, "cross-fitted on the run's other tasks (leave one out)"
    elif args.prior is not None:
        prior, prior_text = LearnedPrior.load(args.prior, world), str(args.prior)
    elif args.prior_tasks == 0:
        prior, prior_text = None, "none"
    else:
        from search.planted import fit_on_planted

        prior, _ = fit_on_planted(world, policy, n=args.prior_tasks)
        prior_text = f"fitted on {args.prior_tasks} planted tasks"
    command = (
        f"dfa experiment unplanted --world {world.name} --kind {args.kind} --tasks {args.tasks} "
        f"--seed {args.seed}"
        + (f" --policy {args.policy}" if args.policy else "")
        + (
            " --prior-fit others"
            if args.prior_fit == "others"
            else f" --prior {args.prior}"
            if args.prior
            else f" --prior-tasks {args.prior_tasks}"
        )
        + f" --out {args.out}"
    )
    bar = tqdm(total=args.tasks, desc=f"{world.name} {args.kind}", unit="task")

    def write(rows: list[dict], sal: list[dict], drawn: int) -> tuple:
        """The rows so far into OUT (an interrupted run keeps the tasks it finished)."""
        bar.update(1)
        run = {
            "world": world.name,
            "policy": args.policy or "base",
            "kind": args.kind,
            "command": command,
            "tasks": len(rows),
            "candidates": drawn,
            "wall_s": round(time.perf_counter() - t0, 1),
            "prior": prior_text,
        }
        return merge(args.out, rows, sal, run)

    written: tuple = ()

    def on_task(rows: list[dict], sal: list[dict], drawn: int) -> None:
        nonlocal written
        written = write(rows, sal, drawn)

    run_world(
        world,
        policy,
        args.kind,
        args.tasks,
        seed=args.seed,
        prior=prior,
        policy_name=args.policy or "base",
        tries=args.tries,
        on_task=on_task,
    )
    bar.close()
    for path in written:
        print(f"  {path}")


def _report(summary, *, items: str, done: str) -> None:
    """What an experiment did, in two lines and the files it wrote."""
    print(
        f"{summary.planned} {items} planned: {summary.skipped} already in {summary.out}, "
        f"{summary.executed} {done} now in {summary.wall_s:.0f} s"
    )
    for path in summary.reports:
        print(f"  {path}")
