"""Behaviour cloning and finetuning: seed, data, model, loop, save — as callable functions."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from policy.model import ImagePolicy, Policy, PolicyConfig
from sim.core import Task, Trajectory, UserError, World


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings for cloning and finetuning."""

    steps: int = 400
    """Gradient steps."""
    batch_size: int = 64
    lr: float = 1e-3
    seed: int = 0
    lr_schedule: str = "constant"
    """"constant", or "cosine": the rate falls along half a cosine to 0 at the last step (each
    DAgger round's fit its own)."""
    shift_px: int = 0
    """Random shifts of each drawn frame, up to this many pixels (shifted); 0: none."""

    def to_dict(self) -> dict:
        """As a recipe holds it: without `lr_schedule` where it is constant and `shift_px`
        where it is 0, so that the recipes of the policies trained before either was chosen
        read back the same."""
        doc = asdict(self)
        if self.lr_schedule == "constant":
            del doc["lr_schedule"]
        if not self.shift_px:
            del doc["shift_px"]
        return doc


BASE = TrainConfig()
FINETUNE = TrainConfig(steps=300, lr=5e-4)
DEMOS_KEPT = 4  # worlds whose training demonstrations a process keeps (training_demos)
_DEMOS: dict[tuple[int, int], tuple[World, tuple[Trajectory, ...]]] = {}  # (id, seed) -> kept
_ROLLOUTS: dict[tuple[int, int], tuple[World, Policy, tuple[Trajectory, ...]]] = {}  # replayed

# loss per step -> None; the recorder and the page draw the curve from these
LossCallback = Callable[[int, float], None]


def transitions(world: World, demos: Sequence[Trajectory]) -> tuple[np.ndarray, np.ndarray]:
    """Stack the (observation, action) pairs of live steps: uint8 (N, H, W, 3), actions (N, ...)."""
    obs, act = [], []
    for d in demos:
        live = [t for t in range(d.horizon) if not world.done(d.scenes[t])]
        obs.append(d.observations[live])
        act.append(d.actions[live])
    return np.concatenate(obs), np.concatenate(act)


def behaviour_clone(
    world: World,
    demos: Sequence[Trajectory],
    *,
    config: TrainConfig = BASE,
    init: Policy | None = None,
    replay: Sequence[Trajectory] = (),
    replay_share: float = 0.5,
    on_loss: LossCallback | None = None,
) -> tuple[Policy, list[float]]:
    """Fit a policy to the demonstrations (from a copy of `init` when given).

    replay: trajectories the policy already knows (its own training demonstrations), mixed
        into every batch as `replay_share` of it so that fitting the new demonstrations does
        not erase what the policy did elsewhere.
    Returns the policy and the loss of every step.
    """
    torch.manual_seed(config.seed)
    gen = np.random.default_rng(config.seed)
    obs, act = transitions(world, demos)  # (N, H, W, 3), (N, A) | (N,)
    if not np.isfinite(act).all():
        raise UserError("cannot train on demonstrations whose actions are not finite numbers")
    n_new = len(obs)
    n_replay = round(config.batch_size * replay_share) if replay else 0
    if n_replay:
        r_obs, r_act = transitions(world, replay)
        obs, act = np.concatenate([obs, r_obs]), np.concatenate([act, r_act])
    if init is not None:
        if init.net is None:
            raise UserError(
                "this policy can be run but not trained (an ONNX graph): finetune a PyTorch, "
                "stable-baselines3 or own checkpoint instead"
            )
        net = init.copy().net
    else:
        net = ImagePolicy(base_arch(world))
    net.train()
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    learning_rate(config, 0)  # an unknown schedule is one line before any work
    x_all = torch.from_numpy(obs)
    if world.discrete:
        y_all = torch.from_numpy(act.astype(np.int64))
        loss_fn: Callable = nn.CrossEntropyLoss()
    else:
        y_all = torch.from_numpy(act.astype(np.float32))

        def loss_fn(pred, y):
            return ((pred - y) ** 2).sum(dim=1).mean()  # mean L2 of the action error

    losses = []
    for step in range(config.steps):
        if n_replay:  # (batch - n_replay) new transitions, then n_replay replayed ones
            idx = torch.from_numpy(
                np.concatenate(
                    [
                        gen.integers(0, n_new, size=config.batch_size - n_replay),
                        gen.integers(n_new, len(x_all), size=n_replay),
                    ]
                )
            )
        else:
            idx = torch.from_numpy(gen.integers(0, n_new, size=min(config.batch_size, n_new)))
        x = shifted(x_all[idx], config.shift_px, gen) if config.shift_px else x_all[idx]
        loss = loss_fn(net(x), y_all[idx])
        value = loss.item()
        if not math.isfinite(value):
            raise UserError(
                f"training stopped at step {step}: the loss is {value}, not a finite number "
                "(the policy or its demonstrations hold non-finite values)"
            )
        for group in opt.param_groups:
            group["lr"] = learning_rate(config, step)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(value)
        if on_loss is not None:
            on_loss(step, losses[-1])
    return (init.with_net(net) if init is not None else Policy(net)), losses


def shifted(frames: torch.Tensor, pad: int, gen: np.random.Generator) -> torch.Tensor:
    """uint8 (B, H, W, 3) -> the same frames, each moved by its own whole-pixel shift of at
    most `pad` along each axis, its edge pixels repeated into the gap it leaves."""
    b, h, w, _ = frames.shape
    x = F.pad(frames.permute(0, 3, 1, 2).float(), (pad,) * 4, mode="replicate")
    dy, dx = gen.integers(0, 2 * pad + 1, size=(2, b))  # (2, B) corners of the crops
    out = torch.stack([x[i, :, dy[i] : dy[i] + h, dx[i] : dx[i] + w] for i in range(b)])
    return out.permute(0, 2, 3, 1).to(torch.uint8)  # (B, H, W, 3)


def learning_rate(config: TrainConfig, step: int) -> float:
    """The learning rate at `step` (0-based) of a fit of `config.steps` steps."""
    if config.lr_schedule == "constant":
        return config.lr
    if config.lr_schedule == "cosine":
        return config.lr * 0.5 * (1 + math.cos(math.pi * step / config.steps))
    raise UserError(f"lr_schedule {config.lr_schedule!r} is not known; accepted: constant, cosine")


def finetune(
    world: World,
    base: Policy,
    demos: Sequence[Trajectory],
    *,
    config: TrainConfig = FINETUNE,
    replay: Sequence[Trajectory] = (),
    replay_share: float = 0.5,
    rounds: int = 0,
    task: Task | None = None,
    on_loss: LossCallback | None = None,
) -> tuple[Policy, list[float]]:
    """Finetune a copy of `base` on the demonstration and its augmentations; base is untouched.

    replay, replay_share: see behaviour_clone (e.g. `training_demos(world)`).
    rounds, task: DAgger rounds after the first fit (see dagger), each rolling the policy out
        from every distinct start of `demos` under `task`'s reward; 0: plain finetuning.
    """
    starts = dict.fromkeys(d.scenes[0] for d in demos) if rounds and task is not None else {}
    return dagger(
        world,
        demos,
        [task.with_scene(s) for s in starts if task is not None],
        rounds=rounds,
        config=config,
        init=base,
        replay=replay,
        replay_share=replay_share,
        on_loss=on_loss,
    )


def expert_relabelled(world: World, task: Task, visited: Trajectory) -> Trajectory:
    """The scenes and frames a rollout visited, each labelled with the expert's action there
    (World.expert_action, closed-loop on the state): what DAgger aggregates."""
    labels = np.stack(
        [np.asarray(world.expert_action(task, s)) for s in visited.scenes[: visited.horizon]]
    )
    return Trajectory(visited.scenes, visited.observations, labels, visited.success)


def dagger(
    world: World,
    demos: Sequence[Trajectory],
    tasks: Sequence[Task],
    *,
    rounds: int,
    config: TrainConfig = BASE,
    init: Policy | None = None,
    replay: Sequence[Trajectory] = (),
    replay_share: float = 0.5,
    on_loss: LossCallback | None = None,
) -> tuple[Policy, list[float]]:
    """Behaviour cloning with DAgger (Ross et al. 2011) and the scripted expert as the labeller:
    clone on `demos` (from a copy of `init` when given, with `replay` as behaviour_clone mixes
    it), then `rounds` times roll the policy out on `tasks`, label every scene it visited with
    the expert's action, add those to the data and clone again from the policy so far
    (config.steps each time, the optimiser's seed moved on by the round).
    Returns the last policy and the loss of every step of every round."""
    fit = {"replay": replay, "replay_share": replay_share}
    policy, losses = behaviour_clone(world, demos, config=config, init=init, on_loss=on_loss, **fit)
    data = list(demos)
    for r in range(1, rounds + 1):
        visited = world.rollout_batch(tasks, policy)
        data += [expert_relabelled(world, t, v) for t, v in zip(tasks, visited, strict=True)]
        policy, more = behaviour_clone(
            world,
            data,
            config=replace(config, seed=config.seed + r),
            init=policy,
            on_loss=None if on_loss is None else _counted_on(on_loss, len(losses)),
            **fit,
        )
        losses += more
    return policy, losses


def _counted_on(on_loss: LossCallback, start: int) -> LossCallback:
    """`on_loss` with steps counted on from `start` (a later round's first step is start)."""
    return lambda step, loss: on_loss(start + step, loss)


def training_tasks(world: World, seed: int = 0) -> list[Task]:
    """The training tasks a base policy is cloned on (world.cloning.demonstrations of them:
    10, the paper's, unless the world declares more; DoorKey 30)."""
    n = world.cloning.demonstrations
    return [world.train_task(seed=seed * n + i) for i in range(n)]


def training_demos(world: World, seed: int = 0) -> list[Trajectory]:
    """The expert demonstrations of the training tasks a base policy is cloned on (with the
    world's action noise, each seeded by its task's seed). Made once per world object for the
    last few asked (a run checks the base policy's recipe with them, then replays them
    while finetuning: 200 MuJoCo demonstrations take minutes)."""
    key = (id(world), seed)  # the world is kept beside its demonstrations: no other takes its id
    if key not in _DEMOS:
        noise = world.cloning.noise
        tasks = training_tasks(world, seed)
        _DEMOS[key] = (world, tuple(world.demonstrate(t, noise=noise, seed=t.seed) for t in tasks))
        while len(_DEMOS) > DEMOS_KEPT:
            del _DEMOS[next(iter(_DEMOS))]
    return list(_DEMOS[key][1])


def replays_rollouts(world: World) -> bool:
    """True where finetuning replays the base policy's own rollouts beside its training
    demonstrations (`replayed`): a world whose base is cloned with DAgger."""
    return world.cloning.dagger_rounds > 0


def replayed(world: World, base: Policy, demos: Sequence[Trajectory]) -> list[Trajectory]:
    """What finetuning `base` replays so that it keeps what it did elsewhere: the training
    demonstrations `demos` and, where the world clones with DAgger (a base fitted on its own
    states too), the base's rollouts on the training tasks, every scene labelled by the expert.
    Replaying the demonstrations alone pulls such a base back toward its first clone. The
    rollouts are made once per base policy for the last few asked."""
    if not replays_rollouts(world):
        return list(demos)
    key = (id(world), id(base))  # both kept beside the rollouts: no other object takes an id
    if key not in _ROLLOUTS:
        tasks = training_tasks(world)
        visited = world.rollout_batch(tasks, base)
        relabelled = tuple(
            expert_relabelled(world, t, v) for t, v in zip(tasks, visited, strict=True)
        )
        _ROLLOUTS[key] = (world, base, relabelled)
        while len(_ROLLOUTS) > DEMOS_KEPT:
            del _ROLLOUTS[next(iter(_ROLLOUTS))]
    return [*demos, *_ROLLOUTS[key][2]]


def clone_base(
    world: World,
    demos: Sequence[Trajectory],
    *,
    seed: int = 0,
    config: TrainConfig = BASE,
    on_loss: LossCallback | None = None,
) -> tuple[Policy, list[float]]:
    """A base policy cloned on the training demonstrations as the world asks
    (World.cloning): plain behaviour cloning, or DAgger on the training tasks of `seed` where
    it asks for rounds of it."""
    rounds = world.cloning.dagger_rounds
    if not rounds:
        return behaviour_clone(world, demos, config=config, on_loss=on_loss)
    tasks = training_tasks(world, seed)
    return dagger(world, demos, tasks, rounds=rounds, config=config, on_loss=on_loss)


def base_arch(world: World) -> PolicyConfig:
    """The architecture a policy cloned for `world` has: the paper's CNN with the head the
    world's cloning asks for (World.cloning.head)."""
    return PolicyConfig(
        world.name, world.obs_shape, world.action_dim, world.discrete, head=world.cloning.head
    )


def base_steps(world: World) -> int:
    """Gradient steps a base policy of `world` takes in all (every DAgger round's too)."""
    return world.cloning.steps * (1 + world.cloning.dagger_rounds)


def base_config(world: World) -> TrainConfig:
    """The settings a world's base policy is cloned with: BASE with the world's steps,
    learning-rate schedule and frame shifts."""
    cloning = world.cloning
    return replace(
        BASE, steps=cloning.steps, lr_schedule=cloning.lr_schedule, shift_px=cloning.shift_px
    )
