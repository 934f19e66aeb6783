"""How a world's policies are made: its base policy cloned from the expert (`Cloning`), and
the finetuning `dfa run` gives it where the paper's settings do not carry (`Adapting`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Cloning:
    """How a world's base policy is cloned from its expert (policy.base, policy.train)."""

    demonstrations: int = 10
    """Training tasks, one expert demonstration each (the paper's 10)."""
    steps: int = 400
    """Gradient steps."""
    noise: float = 0.0
    """Standard deviation of the noise added to the actions a demonstration executes, while it
    keeps the expert's own action as the label (closed-loop worlds: the policy then sees the
    states its small mistakes lead to, and how the expert recovers from them)."""
    dagger_rounds: int = 0
    """DAgger rounds after the first clone (policy.train.dagger): each rolls the policy out on
    the training tasks, labels every scene it visited with `expert_action` (a scripted expert
    closed-loop on the state labels any scene) and clones again on everything so far, from the
    policy so far, `steps` more gradient steps. Still behaviour cloning on the scripted expert;
    0: plain cloning."""
    head: str = "flatten"
    """The policy's head (policy.model.HEADS): "flatten", the paper's; "spatial_softmax",
    keypoints of the trunk's maps, for frames where what matters is a few pixels wide."""
    lr_schedule: str = "constant"
    """The learning rate over each fit's steps (policy.train.TrainConfig.lr_schedule):
    "constant" (the paper's worlds) or "cosine"."""
    shift_px: int = 0
    """Each training frame moved by up to this many pixels along each axis, a fresh shift every
    time it is drawn (policy.train.shifted; Kostrikov et al. 2021's random shift): where things
    are relative to each other matters, not where they fall on the frame. 0: frames as given."""


@dataclass(frozen=True)
class Adapting:
    """The finetuning settings `dfa run` takes by default in a world whose policies the paper's
    settings do not lift (dfa_viz.configs.AdaptConfig.for_world; `dfa run --world W --help`
    shows them). Each field names the option of the same name; None keeps the paper's, and an
    option given on the command line wins."""

    budget: int | None = None
    """Finetuning trajectories."""
    steps: int | None = None
    """Fewest finetuning gradient steps."""
    looks: str | None = None
    """The looks variants take first on each layout ("test" or "spread")."""
    replay_looks: str | None = None
    """The looks of the replayed training data ("training", "varied" or "painted")."""
    dagger_rounds: int | None = None
    """DAgger rounds after finetuning."""
