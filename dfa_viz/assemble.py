"""`dfa run` and `dfa train` put together: world, base policy, failing task, user, recording."""

from __future__ import annotations

import hashlib
import sys
from dataclasses import replace
from pathlib import Path

from tqdm import tqdm

from dfa_viz.configs import PriorArgs, RunArgs
from dfa_viz.loop import run_loop
from dfa_viz.overlay import failed_saliency
from dfa_viz.recording import write_recording
from dfa_viz.run_record import RunRecord
from dfa_viz.users import SimulatedUser
from policy import base_policy, failing_test_task
from policy.base import base_folder
from policy.evaluate import DRAWN
from policy.methods import check_method
from policy.outside import chosen_policy
from policy.saliency import check_explainable
from policy.train import base_steps, training_tasks
from search import SearchConfig
from search.prior import LearnedPrior
from sim import get_world
from sim.core import (
    PRESENCE,
    Task,
    Trajectory,
    UserError,
    World,
    check_demonstration,
    check_seed,
    check_shift,
    files,
    require_success,
)

MAX_EDIT_SIZE = 3


def parse_labels(world: World, labels: tuple[str, ...]) -> dict[tuple[str, str], bool]:
    """'slot.concept=TI|TR' strings -> {(slot, concept): relevant}; names checked against Phi."""
    out: dict[tuple[str, str], bool] = {}
    for text in labels:
        try:
            key, value = text.split("=")
            slot, concept = key.split(".")
        except ValueError:
            raise UserError(
                f"label {text!r} must look like slot.concept=TI or slot.concept=TR"
            ) from None
        s = world.space.slot(slot)
        if concept != PRESENCE or not s.optional:
            s.concept(concept)
        if value not in ("TI", "TR"):
            raise UserError(f"label {text!r}: the answer is TI or TR, not {value!r}")
        if out.get((slot, concept), value == "TR") != (value == "TR"):
            raise UserError(f"--label {slot}.{concept} is given both TI and TR; give one answer")
        out[(slot, concept)] = value == "TR"
    return out


def load_demo(world: World, task: Task, path: Path) -> Trajectory:
    """A user-given demonstration, checked against the task it should demonstrate and replayed
    (sim.core.check_demonstration; an episode of a LeRobotDataset, lerobot:DIR[:episode=N]:
    sim.lerobot.demo); one that does not succeed is refused."""
    from sim.lerobot import demo as lerobot

    if lerobot.is_spec(path):
        spec = lerobot.parse(path)
        demo, source = lerobot.demonstration(world, task, spec), spec.source
    else:
        demo = check_demonstration(world, task, Trajectory.load(path), source=str(path))
        source = str(path)
    require_success(task, demo, source=source)
    return demo


def demo_scene(path: Path):
    """The first scene of a user-given demonstration (the task of a world without test tasks)."""
    from sim.lerobot import demo as lerobot

    if lerobot.is_spec(path):
        return lerobot.first_scene(lerobot.parse(path))
    return Trajectory.load(path).scenes[0]


def train_base(name: str, *, seed: int = 0, retrain: bool = False) -> tuple[Path, float]:
    """Load (checked against today's recipe) or train a world's base policy; returns the
    folder it is kept in and its success on the training tasks."""
    world = get_world(name)
    check_seed(seed)
    bar = tqdm(desc=f"training {name}", unit="step", leave=False, total=base_steps(world))
    policy = base_policy(world, seed=seed, retrain=retrain, on_loss=lambda s, loss: bar.update(1))
    bar.close()
    tasks = training_tasks(world, seed)
    rate = sum(r.success for r in world.rollout_batch(tasks, policy)) / len(tasks)
    return base_folder(world, seed=seed), rate


def fit_prior(args: PriorArgs, *, progress: bool = True) -> tuple[LearnedPrior, int]:
    """Fit a LearnedPrior on `args.tasks` planted size-2 tasks and write it to `args.out`;
    returns it and the seeds tried."""
    from search.planted import fit_on_planted

    world = get_world(args.world)
    if not world.benchmark:
        raise UserError(f"{world.name} has no training tasks to plant in; give a paper world")
    check_seed(args.first_seed, "--first-seed")
    if args.tasks < 1:
        raise UserError(f"--tasks must be at least 1, not {args.tasks}")
    if args.out.is_dir():
        raise UserError(f"--out {args.out} is a folder; give the prior's file name")
    policy = base_policy(world)
    bar = tqdm(total=args.tasks, desc=f"{world.name}: planted tasks", disable=not progress)
    seeds: list[int] = []

    def on_seed(seed: int, accepted: bool) -> None:
        seeds.append(seed)
        bar.update(int(accepted))

    try:
        prior, _ = fit_on_planted(
            world, policy, n=args.tasks, first_seed=args.first_seed, on_seed=on_seed
        )
    finally:
        bar.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    prior.save(args.out)
    return prior, len(seeds)


def run_once(args: RunArgs, *, progress: bool = True) -> RunRecord:
    """The whole loop once, recorded to OUT/<world>-<shift>-seed<seed>.rrd (the file is
    replaced only by a run that completes)."""
    world = get_world(args.world)
    check_shift(args.shift)
    check_seed(args.seed)
    args.adapt.check(world)
    if not 1 <= args.max_size <= MAX_EDIT_SIZE:
        raise UserError(
            f"--max-size must be from 1 to {MAX_EDIT_SIZE} concept changes, not {args.max_size}"
        )
    if not 0.0 <= args.accuracy <= 1.0:
        raise UserError(f"accuracy is a probability in [0, 1], not {args.accuracy}")
    if args.saliency is not None:
        check_method(args.saliency)
    if world.benchmark and args.shift not in world.shifts:
        world.test_task(args.shift, args.seed)  # its one line, before anything is spent
    if args.lerobot is not None:
        from sim.lerobot.writer import check_out

        check_out(args.lerobot)  # its one line, before anything is spent
    overrides = parse_labels(world, args.label)
    learned = None if args.prior is None else LearnedPrior.load(args.prior, world)
    progress = progress and sys.stderr.isatty()  # a status line and bars are a terminal's
    phase = Phases(progress)
    try:
        return _run(args, world, phase, overrides, learned, progress)
    finally:
        phase.close()


class Phases:
    """What `dfa run` is doing now, as one status line on stderr (tqdm, as the bars are), its
    clock restarted at each phase; nothing when progress is off (--json, or stderr is not a
    terminal: a log or a pipe gets the report and one-line errors only)."""

    def __init__(self, on: bool) -> None:
        self.bar = tqdm(
            total=0, desc="starting", bar_format="dfa: {desc} [{elapsed}]", disable=not on
        )

    def __call__(self, text: str) -> None:
        self.bar.set_description_str(text, refresh=False)
        self.bar.reset(total=0)  # the clock from now, shown with the new text

    def close(self) -> None:
        self.bar.close()


def _policy(args: RunArgs, world: World, phase: Phases, progress: bool):
    """The policy `dfa run` diagnoses; the base policy cloned with a bar on first use."""
    if args.policy is not None or args.weights is not None:
        phase(f"loading the policy {args.policy or args.weights}")
        return chosen_policy(world, args.policy, args.weights)
    phase(f"the base policy of {world.name} (cloned on the expert's demonstrations on first use)")
    bar = tqdm(
        total=base_steps(world),
        desc="cloning the base policy",
        leave=False,
        disable=not progress,
    )
    try:
        policy = base_policy(world, on_loss=lambda step, loss: bar.update(1))
    finally:
        bar.close()
    policy.fits(world)
    return policy


def _run(args: RunArgs, world: World, phase: Phases, overrides, learned, progress) -> RunRecord:
    policy = _policy(args, world, phase, progress)
    chosen = args.policy or args.weights
    who = "the base policy" if chosen is None else f"the policy {chosen}"
    if args.saliency is not None:
        check_explainable(policy)
    if world.benchmark:
        phase(f"drawing {args.shift} tasks until {who} fails one (at most {DRAWN})")
        drawn = tqdm(total=DRAWN, desc="tasks drawn", leave=False, disable=not progress)
        try:
            task, _ = failing_test_task(
                world, policy, args.shift, args.seed, who=who, on_draw=lambda k: drawn.update(1)
            )
        finally:
            drawn.close()
        demo = load_demo(world, task, args.demo) if args.demo is not None else None
    elif args.demo is not None:  # no test tasks: the demonstration's first scene is the task
        task = world.task_for(demo_scene(args.demo))
        demo = load_demo(world, task, args.demo)
    else:
        raise UserError(
            f"{world.name} makes no test tasks: give the demonstration to diagnose from (--demo)"
        )
    said = {
        "demonstrate": "the demonstration, then the search for the smallest concept edit",
        "label": f"feedback taken; variants of the demonstration, then finetuning {who}",
    }
    user = SimulatedUser(
        world,
        accuracy=args.accuracy,
        seed=args.seed,
        overrides=overrides,
        demo=demo,
        on_asked=lambda asked: phase(said[asked]),
    )
    bars: dict[str, tqdm] = {}
    steps = args.adapt.total_steps
    n_eval = args.adapt.finetuning.n_eval
    phase(f"rolling {who} out on the test task")

    def bar(key: str, total: int, desc: str) -> tqdm:
        if key not in bars:  # made once: a bar made and dropped still prints a line
            bars[key] = tqdm(total=total, desc=desc, leave=False)
        return bars[key]

    def on_progress(size: int, done: int, total: int) -> None:
        if progress:
            b = bar(f"s{size}", total, f"search, size {size}")
            b.update(done - b.n)

    def on_loss(step: int, loss: float) -> None:
        if progress:
            bar("ft", steps, "finetuning").update(1)
        if step == steps - 1:
            phase(f"scoring both policies on {2 * n_eval} fresh tasks")

    try:
        record = run_loop(
            world,
            policy,
            task,
            user,
            seed=args.seed,
            search=replace(SearchConfig.for_world(world, max_size=args.max_size), learned=learned),
            config=args.adapt,
            on_progress=on_progress,
            on_loss=on_loss,
        )
    finally:
        for bar in bars.values():
            bar.close()
    phase("writing the recording")
    path = args.out / recording_name(
        world, args.shift, args.seed, policy, args.policy, args.weights
    )
    record = replace(record, recording=str(path))
    layer = None
    if args.saliency is not None:
        layer = failed_saliency(world, policy, record, args.saliency)
    write_recording(path, world, record, saliency=layer)
    if args.lerobot is not None:
        from dfa_viz.lerobot.export import export_run
        from policy import training_demos

        phase("writing the LeRobot dataset")
        known = training_demos(world) if world.benchmark and record.adaptation else ()
        exported = export_run(args.lerobot, world, record, known=known)
        record = replace(record, dataset=str(exported.written.root))
    return record


def recording_name(
    world: World, shift: str, seed: int, policy, spec: str | None, weights: Path | None
) -> str:
    """<world>-<shift>-seed<seed>.rrd for the base policy; any other policy adds a short name
    of the file it came from and 8 hex digits of its sha256 (with --weights, of both files'),
    so that runs of different policies on the same task keep their own recordings."""
    base = f"{world.name}-{shift}-seed{seed}"
    if spec is None and weights is None:
        return files.safe_name(f"{base}.rrd")
    if policy.origin is not None:  # a policy from outside: the file its spec reads
        name, digest = Path(policy.origin.file).stem, policy.origin.sha256
    else:  # a checkpoint folder of the project's own
        folder = Path(spec).resolve()
        name, digest = folder.name, files.sha256(folder / "model.safetensors")
    if weights is not None:
        digest = hashlib.sha256(
            f"{digest}{files.sha256(Path(weights) / 'model.safetensors')}".encode()
        ).hexdigest()
    return files.safe_name(f"{base}-{name[:24]}-{digest[:8]}.rrd")
