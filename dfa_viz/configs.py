"""The loop's configs (AdaptConfig, Finetuning) and the options of the core's subcommands (`dfa
run`, `worlds`, `check-world`, `train`, `prior`): one frozen dataclass per command (a docstring
under each field: tyro turns them into the help), shared by the CLI and the function it calls.
Each client's options live beside it, in its own args.py (dfa_viz.app.args, sweep.args,
experiment.args, study.args, bench.args, lerobot.args). Light to import: nothing here loads
torch, MuJoCo, rerun or viser.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Annotated, Literal

import tyro

from sim.core import UserError, World

REPLAY_LOOKS = ("training", "varied", "painted")  # Finetuning.replay_looks


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
    looks: Literal["test", "spread"] = "test"
    """The looks variants take first on each layout: "test", the test task's own (what the
    user saw go wrong); "spread", each TI look's accepted values in turn over the layouts, so
    that a budget shows many of them (spread_looks in policy.variants)."""
    replay_looks: Literal["training", "varied", "painted"] = "training"
    """The looks of the replayed training data: "training", as the base saw it; "varied",
    each replayed trajectory re-rendered once over the TI labels (policy.replay_looks), so
    that the whole training distribution is seen in the looks the user accepts; "painted",
    as varied with each recoloured or added object in a colour of its own beyond the named
    ones (worlds whose renderer draws any colour: the MuJoCo worlds)."""
    n_eval: int = 10
    """Fresh tasks each policy is scored on, on the shift and over all the user wants (the
    paper's 10)."""
    dagger_rounds: int = 0
    """DAgger rounds after finetuning (policy.train.dagger), as a base cloned with them was
    (World.cloning): each rolls the finetuned policy out from the start of every finetuning
    trajectory, labels each scene it visited with the world's scripted expert's action, and
    finetunes again on all of it, as many steps again. The labels come from the simulator's
    expert, not from the user: a simulated user's help. 0: plain finetuning."""

    @property
    def uses_training_demos(self) -> bool:
        """Whether it reads the base policy's training demonstrations (as variant sources, or
        replayed): a MuJoCo world makes them in minutes, so they are made only then."""
        return self.sources == "all" or self.replay_share > 0

    def check(self, world: World | None = None) -> Finetuning:
        """Raise a UserError for a setting out of range (or that `world` cannot do); returns
        self."""
        for name, value in (
            ("steps", self.steps),
            ("steps-per-trajectory", self.steps_per_trajectory),
            ("n-eval", self.n_eval),
        ):
            if value < 1:
                raise UserError(f"--{name} must be at least 1, not {value}")
        if self.dagger_rounds < 0:
            raise UserError(f"--dagger-rounds must be 0 or more, not {self.dagger_rounds}")
        if not 0.0 <= self.replay_share < 1.0:
            raise UserError(
                f"--replay-share is a share of a batch in [0, 1), not {self.replay_share}"
            )
        if self.sources not in ("all", "user"):
            raise UserError(f"--sources is all or user, not {self.sources!r}")
        if self.looks not in ("test", "spread"):
            raise UserError(f"--looks is test or spread, not {self.looks!r}")
        if self.replay_looks not in REPLAY_LOOKS:
            raise UserError(
                f"--replay-looks is {', '.join(REPLAY_LOOKS)}, not {self.replay_looks!r}"
            )
        if world is not None and self.replay_looks == "painted" and world.paints is None:
            raise UserError(
                f"--replay-looks painted needs a world that draws any colour (the MuJoCo "
                f"worlds); {world.name} draws only its named colours: training or varied"
            )
        return self


@dataclass(frozen=True)
class AdaptConfig:
    """How a policy is adapted from one demonstration and the user's feedback."""

    budget: int = 25
    """Finetuning trajectories: the demonstration plus budget - 1 variants of it over the TI
    concepts (repeated from the demonstration on when fewer exist)."""
    finetuning: Annotated[Finetuning, tyro.conf.OmitArgPrefixes] = field(default_factory=Finetuning)
    """How it finetunes and scores."""

    def train_config(self, seed: int, shift_px: int = 0):
        """The finetuning settings (policy.train.TrainConfig) of a run with this budget and
        seed: max(steps, steps_per_trajectory x budget) steps, frames shifted by up to
        `shift_px` (a world's finetuning shifts them as its base was cloned)."""
        from policy.train import FINETUNE, TrainConfig

        f = self.finetuning
        steps = max(f.steps, f.steps_per_trajectory * self.budget)
        return TrainConfig(steps, FINETUNE.batch_size, FINETUNE.lr, seed, shift_px=shift_px)

    @property
    def total_steps(self) -> int:
        """Gradient steps finetuning takes in all: train_config's steps for the first fit and
        as many for each DAgger round."""
        return self.train_config(0).steps * (1 + self.finetuning.dagger_rounds)

    @classmethod
    def for_world(cls, world: World) -> AdaptConfig:
        """The defaults in `world`: the paper's, with the settings its `adapting` names
        (`dfa run --world W` starts from these)."""
        named = {k: v for k, v in asdict(world.adapting).items() if v is not None}
        paper = cls()
        return cls(named.pop("budget", paper.budget), replace(paper.finetuning, **named))

    @classmethod
    def from_dict(cls, d: dict) -> AdaptConfig:
        """Read back dataclasses.asdict(config) (TypeError or KeyError if malformed)."""
        return cls(int(d["budget"]), Finetuning(**d["finetuning"]))

    def check(self, world: World | None = None) -> AdaptConfig:
        """Raise a UserError for a setting out of range (or that `world` cannot do); returns
        self."""
        if self.budget < 1:
            raise UserError(f"--budget must be at least 1, not {self.budget}")
        self.finetuning.check(world)
        return self


@dataclass(frozen=True)
class RunArgs:
    """Run the whole DFA loop once with the simulated user and report what happened.

    Rolls the base policy out on a failing test task of the chosen shift, takes a
    demonstration, searches the smallest concept edit that makes the policy follow it (in a
    closed-loop MuJoCo world: do the task it shows), takes
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
    """How the policy is adapted: the finetuning experiment's defaults, or those the world
    declares (World.adapting: FetchPickAndPlace's); `dfa run --world W --help` shows them."""


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
