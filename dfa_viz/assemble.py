"""Putting a run together: world, base policy, failing task, user, recorder."""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm

from dfa_viz.loop import LoopReport, run_loop
from dfa_viz.recording import Recorder
from dfa_viz.users import SimulatedUser
from policy import Policy, base_policy, failing_test_task, load_policy
from policy.base import base_folder
from policy.train import BASE, training_tasks
from search import SearchConfig
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
    require_success,
)

MAX_EDIT_SIZE = 3


def check_out(out: Path) -> Path:
    """An output folder: created if missing; a file of that name is an error."""
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is a file; give a folder for the recordings")
    return out


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
    (sim.core.check_demonstration); one that does not succeed is refused."""
    demo = check_demonstration(world, task, Trajectory.load(path), source=str(path))
    require_success(task, demo, source=str(path))
    return demo


def train_base(name: str, *, seed: int = 0, retrain: bool = False) -> tuple[Path, float]:
    """Load (checked against today's recipe) or train a world's base policy; returns the
    folder it is kept in and its success on the training tasks."""
    world = get_world(name)
    check_seed(seed)
    bar = tqdm(desc=f"training {name}", unit="step", leave=False, total=BASE.steps)
    policy = base_policy(world, seed=seed, retrain=retrain, on_loss=lambda s, loss: bar.update(1))
    bar.close()
    tasks = training_tasks(world, seed)
    rate = sum(r.success for r in world.rollout_batch(tasks, policy)) / len(tasks)
    return base_folder(world, seed=seed), rate


def run_once(
    world_name: str,
    shift: str,
    seed: int,
    *,
    accuracy: float = 1.0,
    labels: tuple[str, ...] = (),
    policy_dir: Path | None = None,
    demo_path: Path | None = None,
    max_size: int = 2,
    out: Path = Path("recordings"),
    progress: bool = True,
) -> LoopReport:
    """The whole loop once, recorded to out/<world>-<shift>-seed<seed>.rrd."""
    world = get_world(world_name)
    check_shift(shift)
    check_seed(seed)
    check_out(out)
    if not 1 <= max_size <= MAX_EDIT_SIZE:
        raise UserError(
            f"--max-size must be from 1 to {MAX_EDIT_SIZE} concept changes, not {max_size}"
        )
    if not 0.0 <= accuracy <= 1.0:
        raise UserError(f"accuracy is a probability in [0, 1], not {accuracy}")
    overrides = parse_labels(world, labels)
    policy: Policy = load_policy(policy_dir, world=world) if policy_dir else base_policy(world)
    task, _ = failing_test_task(world, policy, shift, seed)
    demo = load_demo(world, task, demo_path) if demo_path is not None else None
    user = SimulatedUser(world, accuracy=accuracy, seed=seed, overrides=overrides, demo=demo)
    path = out / f"{world.name}-{shift}-seed{seed}.rrd"
    bars: dict[int, tqdm] = {}

    def on_progress(size: int, done: int, total: int) -> None:
        if not progress:
            return
        bar = bars.setdefault(size, tqdm(total=total, desc=f"search, size {size}", leave=False))
        bar.update(done - bar.n)

    try:
        with Recorder(path, world, task) as recorder:  # in place only once the run completes
            report = run_loop(
                world,
                policy,
                task,
                user,
                search_config=SearchConfig.for_world(world, max_size=max_size),
                seed=seed,
                observer=recorder,
                on_progress=on_progress,
            )
    finally:
        for bar in bars.values():
            bar.close()
    report.recording = str(path)
    return report
