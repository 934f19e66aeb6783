"""The options of every `dfa` subcommand, written once: one frozen dataclass per command (a
docstring under each field: tyro turns them into the help), shared by the CLI and the function
it calls. Light to import: nothing here loads torch, MuJoCo, rerun or viser.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import tyro

from sim import PAPER_WORLDS
from sim.core import UserError

EXPLAINERS = (
    "counterfactual",
    "integrated_gradients",
    "occlusion",
    "grad_cam",
    "kernel_shap",
    "random",
)
"""The explanation benchmark's explainers: the search, policy.saliency.METHODS in their order,
and the floor; spelled out so that the command line's defaults load no PyTorch (test_explain
holds the middle to METHODS)."""
EXPLAIN_SHIFTS = ("object_ti", "object_tr", "distractor_ti", "distractor_tr")
EXPLAIN_WORLDS = PAPER_WORLDS


@dataclass(frozen=True)
class Finetuning:
    """How a policy is finetuned and scored, whatever the budget; the same for `dfa run`, the
    page and the finetuning experiment."""

    steps: int = 300
    """Fewest finetuning gradient steps (batch and learning rate: policy.train.FINETUNE's)."""
    steps_per_trajectory: int = 10
    """Steps per finetuning trajectory above that: a run takes max(steps, this x budget), so a
    large budget gets as many passes over its data as a small one."""
    replay_share: float = 0.5
    """Share of every finetuning batch replayed from the base policy's training
    demonstrations, so that fitting the new ones does not erase what it did elsewhere."""
    sources: Literal["all", "user"] = "all"
    """What variants are made from: "all" (the base policy's training demonstrations and the
    user's, edited to values the user accepts) or "user" (the user's demonstration only, as in
    the paper)."""
    n_eval: int = 10
    """Fresh tasks each policy is scored on, on the shift and over all the user wants (the
    paper's 10)."""

    def check(self) -> Finetuning:
        """Raise a UserError for a setting out of range; returns self."""
        for name, value in (
            ("steps", self.steps),
            ("steps-per-trajectory", self.steps_per_trajectory),
            ("n-eval", self.n_eval),
        ):
            if value < 1:
                raise UserError(f"--{name} must be at least 1, not {value}")
        if not 0.0 <= self.replay_share < 1.0:
            raise UserError(
                f"--replay-share is a share of a batch in [0, 1), not {self.replay_share}"
            )
        if self.sources not in ("all", "user"):
            raise UserError(f"--sources is all or user, not {self.sources!r}")
        return self


@dataclass(frozen=True)
class AdaptConfig:
    """How a policy is adapted from one demonstration and the user's feedback."""

    budget: int = 25
    """Finetuning trajectories: the demonstration plus budget - 1 variants of it over the TI
    concepts (repeated from the demonstration on when fewer exist)."""
    finetuning: Annotated[Finetuning, tyro.conf.OmitArgPrefixes] = field(default_factory=Finetuning)
    """How it finetunes and scores."""

    def train_config(self, seed: int):
        """The finetuning settings (policy.train.TrainConfig) of a run with this budget and
        seed: max(steps, steps_per_trajectory x budget) steps."""
        from policy.train import FINETUNE, TrainConfig

        f = self.finetuning
        steps = max(f.steps, f.steps_per_trajectory * self.budget)
        return TrainConfig(steps, FINETUNE.batch_size, FINETUNE.lr, seed)

    @classmethod
    def from_dict(cls, d: dict) -> AdaptConfig:
        """Read back dataclasses.asdict(config) (TypeError or KeyError if malformed)."""
        return cls(int(d["budget"]), Finetuning(**d["finetuning"]))

    def check(self) -> AdaptConfig:
        """Raise a UserError for a setting out of range; returns self."""
        if self.budget < 1:
            raise UserError(f"--budget must be at least 1, not {self.budget}")
        self.finetuning.check()
        return self


@dataclass(frozen=True)
class RunArgs:
    """Run the whole DFA loop once with the simulated user and report what happened.

    Rolls the base policy out on a failing test task of the chosen shift, takes a
    demonstration, searches the smallest concept edit that makes the policy follow it, takes
    TI/TR feedback, finetunes on the demonstration and its variants over the TI concepts, and
    scores both policies on 10 fresh tasks that carry the shift (and 10 from all of what the
    user wants). Everything is recorded to OUT/<world>-<shift>-seed<seed>.rrd (another
    policy than the base policy adds its file's name and sha256: -<name>-<8 hex digits>).
    """

    world: str = "nav2d"
    """A registered world (`dfa worlds` lists them) or minigrid:ENV_ID[:tile=N][:view=partial]."""
    shift: str = "object_ti"
    """object_ti, object_tr, distractor_ti, distractor_tr or other."""
    seed: int = 0
    """Selects the test task; the same seed gives the same run."""
    json: bool = False
    """Print the report as one JSON object."""
    accuracy: float = 1.0
    """Probability that each simulated feedback label is right."""
    label: tyro.conf.UseAppendAction[tuple[str, ...]] = ()
    """Fixed answers, e.g. goal.colour=TR or distractor.presence=TI; repeat --label for more."""
    policy: str | None = None
    """The policy to diagnose instead of the base policy: a checkpoint folder
    (model.safetensors + config.json), onnx:PATH.onnx, torch:MODULE:CALLABLE@WEIGHTS or
    sb3:PATH.zip (policy.outside)."""
    weights: Path | None = None
    """Finetuned weights dfa saved for --policy (a folder the page wrote, policy-NNNN): loaded
    into that policy once its file is shown to be the one they were finetuned from."""
    demo: Path | None = None
    """A demonstration .npz (a saved Trajectory), or an episode of a LeRobotDataset
    (lerobot:DIR[:episode=N][:camera=NAME], episode 0 unless named), instead of the scripted
    expert's; replayed, and its frames must be the world's. For a world without test tasks,
    the demonstration's first scene is the task (a dataset must be one dfa exported)."""
    max_size: int = 2
    """The largest edit the search tries (concept changes)."""
    prior: Path | None = None
    """A learned search prior for this world (`dfa prior` writes one, JSON): it orders the
    search's edits by what past searches found; the same edits are tried and found."""
    saliency: str | None = None
    """Also record where the failed rollout's frames push the policy off the demonstration:
    a heat layer `rollouts/failed/saliency` over its frames, by captum's grad_cam (cheap),
    integrated_gradients, occlusion or kernel_shap (the project's own image policies only)."""
    out: Path = Path("recordings")
    """Folder for the recording."""
    lerobot: Path | None = None
    """Also write the run's trajectories (demonstration, variants, counterfactuals, failed and
    finetuned rollouts) as a LeRobotDataset v3.0 in this folder (see `dfa export lerobot`)."""
    adapt: Annotated[AdaptConfig, tyro.conf.OmitArgPrefixes] = field(default_factory=AdaptConfig)
    """How the policy is adapted (the finetuning experiment's defaults)."""


@dataclass(frozen=True)
class WorldsArgs:
    """List every registered world with its concept space in one line (and what it can do)."""

    names: tuple[str, ...] = ()
    """Only these worlds (e.g. minigrid:MiniGrid-DoorKey-5x5-v0); default: every registered one."""


@dataclass(frozen=True)
class CheckWorldArgs:
    """Run the world contract on one world and print a line per part: PASS, or FAIL and why.

    The checks tests/sim/test_world_contract.py runs on every registered world (sim.contract):
    gymnasium's check_env on the world's environment, rendering and stepping deterministic and
    the same batched as one by one, encode/decode and edit round trips, the capabilities
    declared, no success from a non-finite state, and for a world with test tasks its shifts,
    expert and fresh tasks. Exits 0 when every part holds, 1 when one fails.
    """

    name: tyro.conf.Positional[Annotated[str, tyro.conf.arg(metavar="NAME")]]
    """The world: a registered name (`dfa worlds`), module:Class (a World subclass or a
    function returning one, imported from PYTHONPATH or the current folder), or
    minigrid:ENV_ID."""


@dataclass(frozen=True)
class TrainArgs:
    """Load the committed base policy of each world, checked against today's training recipe,
    and report its success on the training tasks; --retrain trains it again and writes it where
    it is kept (policy/weights/<world>/: commit the new files)."""

    worlds: tuple[str, ...] = ("nav2d",)
    """Which worlds."""
    seed: int = 0
    """Training seed (0: the policies of record; others are cached outside the repository)."""
    retrain: bool = False
    """Train again instead of loading."""


@dataclass(frozen=True)
class BenchArgs:
    """Measure every speed figure on this machine and write them to benchmarks/ as Markdown.

    Each world's search against a naive one-candidate-at-a-time loop timed in the same
    process, a whole `dfa run`, the tabletop's edit + render and search targets, per world the
    render throughput, finetuning time, recording size and one experiment run, and the web page
    (load, slider latency, finetune round trip).
    """

    worlds: tuple[str, ...] = (*PAPER_WORLDS, "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12")
    """Which worlds to measure (the MiniGrid one with the stable-baselines3 agent of
    docs/examples)."""
    repeats: int = 3
    """Timing repeats (the best is reported)."""
    page: bool = True
    """Also measure the web page in Chromium (a minute or two)."""
    out: Path = Path("benchmarks") / "latest.md"
    """The Markdown report."""
    prior_tasks: int = 100
    """Planted size-2 tasks per paper world on which the learned search prior is measured
    against enumeration and the first-step prior (dfa_viz.bench.prior)."""


@dataclass(frozen=True)
class PriorArgs:
    """Fit a learned search prior on planted size-2 tasks of a world and write it as JSON.

    Each planted task is a training layout with two looks changed that only an edit of two
    changes explains (search.planted); the prior learns from those searches which single
    changes belong to the answer, and `dfa run --prior FILE` orders its search by it.
    """

    world: str = "nav2d"
    """A paper world (one with training tasks): nav2d, doorkey or tabletop."""
    tasks: int = 50
    """Planted tasks to fit on (the tabletop takes a few seconds each)."""
    first_seed: int = 0
    """Seeds are tried from here up until that many tasks are accepted."""
    out: Path = Path("priors") / "prior.json"
    """Where the prior is written (replaced whole)."""


@dataclass(frozen=True)
class ServeArgs:
    """Serve the feedback web page: pick a task, demonstrate, diagnose, mark TI/TR, adapt.

    Binds 127.0.0.1 unless --host says otherwise; prints the URL. Every user action is appended
    to the session folder as JSON lines before the page acknowledges it; --session DIR resumes.
    """

    world: str = "nav2d"
    """The world the page opens on (any `dfa worlds` lists, or minigrid:ENV_ID)."""
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None
    """When left out, 8080 or the next free one; a port given must be free (0: any)."""
    host: str = "127.0.0.1"
    """The interface to bind; 0.0.0.0 exposes the page to the network."""
    session: Path | None = None
    """A session folder to resume (default: a new one under recordings/sessions/)."""
    policy: str | None = None
    """The policy to diagnose in --world instead of its base policy (as for `dfa run`)."""
    weights: Path | None = None
    """Finetuned weights dfa saved for --policy (as for `dfa run`)."""
    demos: Path | None = None
    """A LeRobotDataset folder whose episodes the page offers as demonstrations: those that
    start from the task's scene (every one, for a dataset that names no scenes)."""
    out: Path = Path("recordings")
    """Folder for the recordings and new sessions."""
    adapt: Annotated[AdaptConfig, tyro.conf.OmitArgPrefixes] = field(default_factory=AdaptConfig)
    """How "Augment & finetune" adapts (the finetuning experiment's defaults)."""


@dataclass(frozen=True)
class DemoArgs:
    """Open the feedback page on a default scenario, the diagnosis already computed.

    The failed rollout, the expert's demonstration and the counterfactual are ready to scrub;
    mark the edited concepts TI or TR and press "Augment & finetune". Ctrl-C stops the server.
    """

    world: str = "nav2d"
    """The world of the scenario."""
    shift: str = "distractor_ti"
    """The shift of the scenario."""
    seed: int = 0
    """The seed of the scenario."""
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None
    """When left out, 8080 or the next free one; a port given must be free (0: any)."""
    host: str = "127.0.0.1"
    """The interface to bind; 0.0.0.0 exposes the page to the network."""
    out: Path = Path("recordings")
    """Folder for the recordings and the session."""
    adapt: Annotated[AdaptConfig, tyro.conf.OmitArgPrefixes] = field(default_factory=AdaptConfig)
    """How "Augment & finetune" adapts (the finetuning experiment's defaults)."""


@dataclass(frozen=True)
class SweepArgs:
    """Find what breaks a policy before a user meets it: every single concept edit on many tasks.

    On TASKS tasks of the training distribution (seeds SEED, SEED + 1, ...), every value of
    every concept of every slot, and every object added or removed, is rolled out in lockstep
    beside the unedited task; an added object also where the world says it is in the way (a
    DoorKey lava on the path). Each edit's failure rate at what the task asks for (counted
    where the expert can still do it) and its mean action deviation from the unedited
    rollout, with 95% intervals; edits and concepts ranked, most damaging first. With
    --sizes 1 2, pairs of the edits that move the policy most, and those that fail more often
    than both alone.

    Writes OUT/sweep.csv, OUT/heatmap.png (failure rate, slot.concept x value) and
    OUT/sweep.rrd (the heatmap, a bar chart per concept, the worst edited rollouts beside the
    unedited ones), and prints the ranking. The same tasks give the same files on every
    backend. `dfa serve` has the same sweep in its Sweep tab, a click loading a failure.
    """

    world: str = "nav2d"
    """A registered world (`dfa worlds` lists them)."""
    policy: str | None = None
    """The policy to sweep instead of the base policy (a checkpoint folder, onnx:, torch:,
    sb3:, as for `dfa run`)."""
    tasks: int = 100
    """How many tasks (the same scene is rolled out once however often it comes)."""
    seed: int = 0
    """The first task's seed."""
    sizes: tuple[int, ...] = (1,)
    """Edit sizes: 1 (single edits), 1 2 (and pairs)."""
    workers: int = 1
    """Units of work side by side (1: in this process; more: a process pool or Ray CPUs)."""
    backend: Literal["local", "ray"] = "local"
    """local (processes on this machine) or ray (pip install 'dfa[ray]')."""
    out: Path | None = None
    """The folder for the files; when left out, recordings/sweep/<world>."""
    worst: int = 4
    """Edited rollouts shown in the recording, beside their unedited ones."""
    pair_cells: int = 32
    """With pairs: the edits paired, those that move the policy most."""
    ray_address: str | None = None
    """An existing Ray cluster ("auto", "ray://host:10001"); default: start one here."""
    progress: bool = True
    """Show a progress bar."""


Condition = Literal["nh_random", "baseline_h", "cf_h", "oracle"]


@dataclass(frozen=True)
class Q2Args:
    """Reproduce the paper's finetuning comparison: success against finetuning trajectories.

    For every world, shift, condition, budget and seed, one run takes the first task-irrelevant
    test task of that seed the base policy fails, the expert's demonstration of it, and a
    concept to mark task-irrelevant: NH-random a random concept for each variant; Baseline H a
    simulated user who names the right concept at the paper's rate without counterfactuals;
    CF H one who sees the loop's real diagnosis and names the right concept at the paper's
    rate with counterfactuals (never when the search found nothing or the wrong thing); Oracle
    always the right one. The budget is the number of finetuning trajectories: the
    demonstration plus budget - 1 distinct variants over the concept (same actions, edited
    states), repeated from the demonstration on when the concept has fewer variants. The
    adaptation is `dfa run`'s own (loop.adapt); both policies are scored on fresh tasks that
    carry the test task's shift, and on fresh tasks from all of what the user wants.

    Writes OUT/runs.csv (every run), OUT/table.md (means with 95% confidence intervals beside
    the paper's numbers, and whether CF H beats Baseline H), OUT/plots/<world>-<shift>.png and
    OUT/curves.rrd. Runs already in OUT/runs.csv are skipped, so an interrupted experiment
    resumes where it stopped. The same seeds give the same runs.csv whichever backend ran them.
    """

    worlds: Annotated[tuple[Literal[PAPER_WORLDS], ...], tyro.conf.arg(aliases=("--world",))] = (
        PAPER_WORLDS
    )
    """Which of the paper's worlds."""
    shift: Literal["object", "distractor", "both"] = "both"
    """object, distractor, or both."""
    budgets: tuple[int, ...] = (5, 10, 25, 50, 75, 100)
    """Finetuning trajectories per run (the demonstration counts as one)."""
    seeds: int = 5
    """Seeds 0 .. SEEDS-1 (each picks a test task and every random choice of its runs)."""
    workers: int = 2
    """Runs executed side by side (processes locally, CPUs of a local Ray instance)."""
    backend: Literal["local", "ray"] = "local"
    """local (a process pool on this machine) or ray (pip install 'dfa[ray]')."""
    out: Path = Path("recordings/experiments/q2")
    """The results folder."""
    conditions: tuple[Condition, ...] = ("nh_random", "baseline_h", "cf_h", "oracle")
    """Which conditions."""
    max_size: int = 2
    """Largest edit the counterfactual search tries (CF H)."""
    ray_address: str | None = None
    """An existing Ray cluster ("auto", "ray://host:10001"); default: start one here."""
    progress: bool = True
    """Show a progress bar."""
    finetuning: Annotated[Finetuning, tyro.conf.OmitArgPrefixes] = field(default_factory=Finetuning)
    """How every run finetunes and scores (its budget is one of --budgets)."""


@dataclass(frozen=True)
class ExplainArgs:
    """Measure how well each explanation names the planted cause of a failure.

    For every world, shift and seed, the first test task of that seed the base policy fails,
    its failed rollout and the expert's demonstration. Each explainer ranks the concepts the
    test scene shows: the counterfactual search (the concepts its best edit changes first);
    captum's Integrated Gradients, Occlusion, Grad-CAM and KernelSHAP over the failed
    rollout's frames against the demonstrated actions, reduced to the attribution inside each
    object's pixels; a random order as the floor. A hit is the planted cause ranked first
    (top-1) or among the first three (top-3).

    Writes OUT/tasks.csv (every task and explainer), OUT/timings.csv, OUT/table.md (hit rates
    with 95% Wilson intervals beside the paper's user accuracies, and time per task) and
    OUT/hits.png. Tasks already in OUT/tasks.csv are skipped, so an interrupted benchmark
    resumes where it stopped; the same seeds give the same tasks.csv on either backend.
    """

    worlds: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--world",))] = EXPLAIN_WORLDS
    """Which worlds (any that makes test tasks: `dfa worlds` says which)."""
    shifts: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--shift",))] = EXPLAIN_SHIFTS
    """Which shifts (those with a planted cause: object_ti, object_tr, distractor_ti, ...)."""
    tasks: int = 50
    """Tasks per world and shift: seeds 0 .. TASKS-1."""
    methods: Annotated[tuple[str, ...], tyro.conf.arg(aliases=("--method",))] = EXPLAINERS
    """Which explainers (counterfactual, integrated_gradients, occlusion, grad_cam, ...)."""
    workers: int = 2
    """Tasks explained side by side (processes locally, CPUs of a local Ray instance)."""
    backend: Literal["local", "ray"] = "local"
    """local (a process pool on this machine) or ray (pip install 'dfa[ray]')."""
    out: Path = Path("recordings/experiments/explain")
    """The results folder."""
    max_size: int = 2
    """Largest edit the counterfactual search tries."""
    ray_address: str | None = None
    """An existing Ray cluster ("auto", "ray://host:10001"); default: start one here."""
    progress: bool = True
    """Show a progress bar."""


@dataclass(frozen=True)
class NewStudyArgs:
    """Make a user study's tasks once and freeze them in a folder (the paper's user study).

    The protocol (a TOML file) names the tasks per world and shift kind (the paper's: one per
    kind in nav2d and DoorKey, two in the tabletop, TI and TR half and half), the conditions
    (none, counterfactual, saliency, both), the design (between or within subjects) and a seed.
    Every task (the failed rollout, the demonstration, the counterfactual, the saliency maps)
    is computed here, so every participant sees the same ones. Then `dfa study serve OUT`.
    """

    out: Path
    """The new study folder."""
    protocol: Path | None = None
    """study.toml (see README "Running a user study"); left out: the paper's protocol with
    conditions none and counterfactual, within subjects, seed 0."""


@dataclass(frozen=True)
class ServeStudyArgs:
    """Serve a frozen study to participants: each tab enters an anonymous code, goes through
    the familiarisation and answers every question; answers are on disk before the page moves
    on, and a code entered again resumes at its first unanswered question."""

    folder: tyro.conf.Positional[Path]
    """The study folder (`dfa study new`)."""
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None
    """When left out, 8080 or the next free one; a port given must be free (0: any)."""
    host: str = "127.0.0.1"
    """The interface to bind; 0.0.0.0 exposes the page to the network."""


@dataclass(frozen=True)
class AnalyseStudyArgs:
    """Score a study's answers by the paper's rule and compare the conditions: accuracy per
    world, shift kind and condition with standard errors beside the paper's, chi-squared (1)
    between conditions per world, Wilcoxon signed-rank between TR and TI answers. Writes
    FOLDER/analysis/answers.csv, accuracy.md, accuracy.png and answers.rrd."""

    folder: tyro.conf.Positional[Path]
    """The study folder."""


@dataclass(frozen=True)
class ExportArgs:
    """Write dfa's robot-learning data as a LeRobotDataset v3.0 folder, the dataset format
    LeRobot trains from (meta/info.json, parquet tables, AV1 videos for camera frames).

    `dfa export lerobot --from FOLDER --out DIR` reads a page session (session.jsonl), a
    `dfa sweep` folder (sweep.csv) or a `dfa experiment q2` results folder (runs.csv) and
    writes one episode per trajectory: the demonstration, each variant finetuned on, the
    counterfactual rollouts, the failed rollout and the finetuned one (a sweep: each example
    failure and the expert's demonstration of it; q2: each run's demonstration, variants and
    failed rollout), task = the instruction, with dfa's columns dfa.role, dfa.edit,
    dfa.concept, dfa.label, dfa.action_distance, dfa.scene and dfa.run. `dfa run --lerobot DIR`
    writes one run's. Read it back with `dfa view DIR` or `--demo lerobot:DIR:episode=N`.
    """

    format: tyro.conf.Positional[Literal["lerobot"]]
    """The dataset format (LeRobotDataset v3.0)."""
    source: Annotated[Path, tyro.conf.arg(name="from", metavar="FOLDER")]
    """A page session folder, a `dfa sweep` output folder or a q2 results folder."""
    out: Path
    """The dataset folder: new, empty, or a dataset this replaces once the new one is whole."""
    world: str | None = None
    """Only this world's runs (a session or q2 folder); a sweep's world (default: the sweep
    folder's name, as `dfa sweep` names it)."""
    policy: str | None = None
    """The policy the session or sweep ran, when not the base policy (as `dfa run --policy`)."""
    weights: Path | None = None
    """Finetuned weights for --policy (as `dfa run --weights`)."""
    fps: int = 10
    """Frames per second written in the dataset (its timestamps are frame / fps)."""
    frames: Literal["auto", "image", "video"] = "auto"
    """auto: AV1 video for a camera's frames (tabletop, Fetch), PNG images for frames drawn to
    the pixel (nav2d, doorkey, MiniGrid: lossless); or force one."""


@dataclass(frozen=True)
class ViewArgs:
    """Write every episode of a LeRobotDataset (anyone's, or one dfa exported) into one Rerun
    recording: the episodes side by side on one `step` timeline, a tab per episode (its frames,
    one plot per action dimension, its task and dfa's columns) after a tab of all of them (a
    grid of frames, every episode's actions per dimension). Open it with `rerun FILE`."""

    dataset: tyro.conf.Positional[Path]
    """The dataset folder (meta/info.json, data/, videos/)."""
    out: Path | None = None
    """The .rrd to write; default recordings/<dataset folder name>.rrd."""
    episodes: tuple[int, ...] = ()
    """Only these episodes (default: all, up to 500)."""
    camera: str | None = None
    """The image or video feature to show (default the first), e.g. main or
    observation.images.main."""
