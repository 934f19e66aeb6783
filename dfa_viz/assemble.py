"""Putting a run together: world, base policy, failing task, user, recorder."""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm

from dfa_viz.loop import LoopReport, run_loop
from dfa_viz.recording import Recorder
from dfa_viz.users import SimulatedUser
from policy import Policy, base_policy, evaluate, failing_test_task, load_policy
from policy.train import cache_dir
from search import SearchConfig
from sim import get_world
from sim.core import PRESENCE, Task, Trajectory, UserError, World, check_shift


def parse_labels(world: World, labels: tuple[str, ...]) -> dict[tuple[str, str], bool]:
    """'slot.concept=TI|TR' strings -> {(slot, concept): relevant}; names checked against Phi."""
    out = {}
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
        out[(slot, concept)] = value == "TR"
    return out


def load_demo(world: World, task: Task, path: Path) -> Trajectory:
    """A user-given demonstration, checked against the task it should demonstrate."""
    demo = Trajectory.load(path)
    if demo.scenes[0] != task.scene:
        raise UserError(f"{path}: the demonstration starts from another scene than the test task")
    if demo.horizon != world.horizon:
        raise UserError(
            f"{path}: {demo.horizon} steps, but {world.name} episodes have {world.horizon}"
        )
    want = () if world.discrete else (world.action_dim,)
    if demo.actions.shape[1:] != want:
        raise UserError(f"{path}: actions of shape {demo.actions.shape[1:]}, expected {want}")
    return demo


def train_base(name: str, *, seed: int = 0, retrain: bool = False) -> tuple[Path, float]:
    """Train or load a world's base policy; returns its cache folder and training success."""
    world = get_world(name)
    bar = tqdm(desc=f"training {name}", unit="step", leave=False)
    policy = base_policy(world, seed=seed, retrain=retrain, on_loss=lambda s, loss: bar.update(1))
    bar.close()
    rate = evaluate(world, policy, world.train_task(seed), n=10, seed=seed)
    folder = max((cache_dir() / "policies").glob(f"{name}-*"), key=lambda p: p.stat().st_mtime)
    return folder, rate


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
    if not 0.0 <= accuracy <= 1.0:
        raise UserError(f"accuracy is a probability in [0, 1], not {accuracy}")
    overrides = parse_labels(world, labels)
    policy: Policy = load_policy(policy_dir, world=world.name) if policy_dir else base_policy(world)
    task, _ = failing_test_task(world, policy, shift, seed)
    demo = load_demo(world, task, demo_path) if demo_path is not None else None
    user = SimulatedUser(world, accuracy=accuracy, seed=seed, overrides=overrides, demo=demo)
    path = out / f"{world.name}-{shift}-seed{seed}.rrd"
    recorder = Recorder(path, world, task)
    bars: dict[int, tqdm] = {}

    def on_progress(size: int, done: int, total: int) -> None:
        if not progress:
            return
        bar = bars.setdefault(size, tqdm(total=total, desc=f"search, size {size}", leave=False))
        bar.update(done - bar.n)

    try:
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
        recorder.close()
    report.recording = str(path)
    return report
