"""The image policy: the paper's CNN trunk (conv 32/64/32, kernels 8/4/3, strides 4/2/1)."""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from sim.core import UserError, files


@dataclass(frozen=True)
class PolicyConfig:
    """Architecture of one policy; saved as config.json beside the weights."""

    world: str
    obs_shape: tuple[int, int, int]
    """(H, W, 3) of the uint8 observations."""
    action_dim: int
    """Continuous action size, or the number of discrete actions."""
    discrete: bool
    """True: logits head and cross-entropy. False: regression head and L2."""
    channels: tuple[int, int, int] = (32, 64, 32)
    kernels: tuple[int, int, int] | None = None
    """Square kernels of the three convolutions; None: the paper's (8, 4, 3) where the frames
    are large enough for them, else the first of TRUNKS that fits (fitted_trunk)."""
    strides: tuple[int, int, int] | None = None
    """Their strides; None: as `kernels` (the paper's (4, 2, 1))."""
    hidden: int = 100
    head: str = "flatten"
    """What the trunk's feature maps become before the hidden layer (HEADS): "flatten", the
    paper's, every cell of every map; "spatial_softmax", each map's expected (x, y) under a
    softmax over its cells (Levine et al. 2016's keypoints), with a finer trunk by default
    (SPATIAL_TRUNK): where small things are, not what every cell holds."""

    def __post_init__(self) -> None:
        if self.kernels is None or self.strides is None:
            kernels, strides = fitted_trunk(self.obs_shape, self.head)
            object.__setattr__(self, "kernels", self.kernels or kernels)
            object.__setattr__(self, "strides", self.strides or strides)

    def to_dict(self) -> dict:
        """As config.json holds it: without `head` where it is the paper's, so that the
        configs and recipes written before heads were chosen read back the same."""
        doc = asdict(self)
        if self.head == "flatten":
            del doc["head"]
        return doc


TRUNKS = (
    ((8, 4, 3), (4, 2, 1)),  # the paper's: frames of 36 px and more
    ((8, 4, 3), (2, 2, 1)),  # 22 px and more
    ((8, 4, 3), (2, 1, 1)),  # 18
    ((4, 4, 3), (2, 1, 1)),  # 14
    ((3, 3, 3), (1, 1, 1)),  # 7
    ((2, 2, 2), (1, 1, 1)),  # 4
    ((1, 1, 1), (1, 1, 1)),  # any
)
"""Kernels and strides from the paper's trunk down, each fitting smaller frames."""
SPATIAL_TRUNK = ((8, 4, 3), (2, 2, 1))
"""The spatial-softmax head's trunk where it fits (84 px frames: 16 x 16 maps, not the paper
trunk's 7 x 7): keypoints finer than a few pixels of the frame."""
HEADS = ("flatten", "spatial_softmax")


def smallest_side(kernels, strides) -> int:
    """The smallest frame side (px) the convolutions leave at least one pixel of."""
    side = 1
    for k, s in zip(reversed(kernels), reversed(strides), strict=True):
        side = (side - 1) * s + k
    return side


def fitted_trunk(
    obs_shape, head: str = "flatten"
) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
    """(kernels, strides): the first of TRUNKS whose convolutions fit frames of `obs_shape`
    (H, W, 3), judged by the smaller side: the paper's trunk wherever it fits, so that every
    policy that could be built before is built the same (the spatial-softmax head: first
    SPATIAL_TRUNK)."""
    side = min(int(obs_shape[0]), int(obs_shape[1]))
    first = (SPATIAL_TRUNK,) if head == "spatial_softmax" else ()
    for kernels, strides in (*first, *TRUNKS):
        if smallest_side(kernels, strides) <= side:
            return kernels, strides
    return TRUNKS[-1]


class SpatialSoftmax(nn.Module):
    """(B, C, H, W) feature maps -> (B, 2C): each map's expected (x, y) in [-1, 1] under a
    softmax over its cells, at a learnt temperature."""

    def __init__(self, h: int, w: int) -> None:
        super().__init__()
        ys, xs = torch.meshgrid(
            torch.linspace(-1.0, 1.0, h), torch.linspace(-1.0, 1.0, w), indexing="ij"
        )
        self.register_buffer("grid", torch.stack([xs.reshape(-1), ys.reshape(-1)], 1), False)
        self.log_temperature = nn.Parameter(torch.zeros(()))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c = x.shape[:2]
        weights = torch.softmax(x.reshape(b, c, -1) / self.log_temperature.exp(), dim=-1)
        return (weights @ self.grid).reshape(b, 2 * c)  # (B, C, HW) @ (HW, 2)


class Explainable(nn.Module):
    """A network the saliency methods (policy.saliency) can take apart: its outputs from float
    frames, differentiable in the pixels, and its convolutions (Grad-CAM's layer among them)."""

    frame_shape: tuple[int, int, int]
    """(H, W, 3) of the frames it takes."""

    def pixels(self, obs: torch.Tensor) -> torch.Tensor:
        """The network's outputs from float32 pixel values (B, H, W, 3) in [0, 255]."""
        raise NotImplementedError

    def convolutions(self) -> list[nn.Conv2d]:
        """The convolutions the frames go through, in order."""
        raise NotImplementedError


class ImagePolicy(Explainable):
    """uint8 (B, H, W, 3) -> actions float32 (B, A) or logits float32 (B, n_actions).

    Pixel normalisation lives inside the model; GroupNorm, not BatchNorm, so that a batch of
    one behaves like a batch of many.
    """

    def __init__(self, config: PolicyConfig) -> None:
        super().__init__()
        self.config = config
        layers: list[nn.Module] = []
        c_in = 3
        for c, k, s in zip(config.channels, config.kernels, config.strides, strict=True):
            layers += [nn.Conv2d(c_in, c, k, s), nn.GroupNorm(8, c), nn.ReLU()]
            c_in = c
        h, w, _ = config.obs_shape
        if config.head == "spatial_softmax":
            layers.pop()  # the softmax takes the last maps as they are, negative cells too
            with torch.no_grad():
                maps = nn.Sequential(*layers)(torch.zeros(1, 3, h, w)).shape[-2:]
            layers.append(SpatialSoftmax(*maps))
        else:
            layers.append(nn.Flatten())
        self.trunk = nn.Sequential(*layers)
        with torch.no_grad():
            n_flat = self.trunk(torch.zeros(1, 3, h, w)).shape[1]
        self.head = nn.Sequential(
            nn.Linear(n_flat, config.hidden), nn.ReLU(), nn.Linear(config.hidden, config.action_dim)
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        assert obs.dtype == torch.uint8 and obs.shape[1:] == self.config.obs_shape, (
            f"expected uint8 (B, {', '.join(map(str, self.config.obs_shape))}), "
            f"got {obs.dtype} {tuple(obs.shape)}"
        )
        x = obs.float().permute(0, 3, 1, 2)  # (B, 3, H, W), a new tensor: scaled in place
        return self.head(self.trunk(x.div_(127.5).sub_(1.0)))  # the same numbers as pixels'

    def pixels(self, obs: torch.Tensor) -> torch.Tensor:
        """The same outputs from float32 pixel values (B, H, W, 3) in [0, 255]: differentiable
        in the frames (what attributions take gradients of)."""
        x = obs.permute(0, 3, 1, 2) / 127.5 - 1.0  # (B, 3, H, W) in [-1, 1]
        return self.head(self.trunk(x))

    @property
    def frame_shape(self) -> tuple[int, int, int]:  # type: ignore[override]
        return self.config.obs_shape

    def convolutions(self) -> list[nn.Conv2d]:
        return [m for m in self.trunk if isinstance(m, nn.Conv2d)]


@dataclass(frozen=True)
class Origin:
    """What a policy from outside was loaded from, as data: its loader's kind and the name and
    sha256 of the file it read. A finetuned copy records it (config.json "origin") instead of
    anything that could be imported or run, and is loaded only beside the same policy given
    again on the command line."""

    kind: str
    """The loader's prefix: "sb3", "torch", "onnx" or one registered from outside."""
    file: str
    """The file's name (no folder: where it lies is the command line's business)."""
    sha256: str
    """The file's bytes' hex sha256."""

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def of_file(cls, kind: str, path: Path) -> Origin:
        """The origin of a policy its loader `kind` read from the file at `path`."""
        return cls(kind, path.name, files.sha256(path))

    def __str__(self) -> str:
        return f"the {self.kind} policy {self.file} (sha256 {self.sha256[:12]}…)"


CHUNK_VALUES = 1_500_000
"""Pixel values (H x W x 3 per frame) in one forward batch: the activations of a batch this
size stay in the processor's caches. Larger batches are slower per frame (measured: the
tabletop's 80x80 frames run 4x slower per frame in batches of 1024 than of 64; 36x36 frames
are fastest in batches of a few hundred)."""


class Policy:
    """Any policy as a function of numpy observations: the one protocol the search, the loop
    and the page use, whatever made the policy (policy.outside loads the others).

    outputs(obs uint8 (B, H, W, 3)) -> float32 (B, A) actions, or (B, n) scores of the n
    discrete actions (logits, or anything whose argmax is the action); act() is their action.
    `net` is the torch module that maps a uint8 (B, H, W, 3) tensor to those outputs, which
    finetuning trains; None for a policy that can only be run (an ONNX graph).

    discrete, obs_shape (H, W, 3), action_dim: what the policy takes and gives, checked
    against a world before use (fits). source: the spec it was loaded from, as the user typed
    it (None for the project's own checkpoints, whose config.json says everything); it is never
    written to a checkpoint. origin: what that spec read (Origin), which a finetuned copy
    records. chunk: frames per forward batch; by default as many as fit CHUNK_VALUES.
    save_beside(policy, folder): what its loader writes beside a checkpoint of a finetuned
    copy, in the policy's own format (sb3: the zip stable-baselines3 opens); None: nothing.
    """

    def __init__(
        self,
        net: torch.nn.Module | None,
        *,
        discrete: bool | None = None,
        obs_shape: tuple[int, int, int] | None = None,
        action_dim: int | None = None,
        source: str | None = None,
        origin: Origin | None = None,
        chunk: int | None = None,
        save_beside: Callable[[Policy, Path], object] | None = None,
    ) -> None:
        config = getattr(net, "config", None)  # the project's ImagePolicy carries its own
        self.net = net.eval() if net is not None else None
        self.discrete = config.discrete if discrete is None else discrete
        self.obs_shape = tuple(config.obs_shape if obs_shape is None else obs_shape)
        self.action_dim = config.action_dim if action_dim is None else action_dim
        self.source = source
        self.origin = origin
        self.chunk = chunk or max(1, CHUNK_VALUES // int(np.prod(self.obs_shape)))
        self.save_beside = save_beside

    @property
    def config(self) -> PolicyConfig:
        """The architecture of the project's own policies (an ImagePolicy's config)."""
        return self.net.config

    def with_net(self, net: torch.nn.Module) -> Policy:
        """This policy with another module of the same kind (e.g. a finetuned copy)."""
        twin = copy.copy(self)
        twin.net = net.eval()
        return twin

    def copy(self) -> Policy:
        return self.with_net(copy.deepcopy(self.net)) if self.net is not None else self

    def _forward(self, obs: np.ndarray) -> np.ndarray:
        """float32 (B, A | n) of a uint8 (B, H, W, 3) batch."""
        with torch.inference_mode():
            return self.net(torch.from_numpy(np.ascontiguousarray(obs))).float().numpy()

    def outputs(self, obs: np.ndarray) -> np.ndarray:
        """Raw outputs float32 (B, A): actions, or scores (logits) for discrete worlds.

        Raises UserError when any output is not a finite number: nothing downstream (a
        rollout, the search, a success rate) may be computed from one.
        """
        if len(obs) <= self.chunk:
            out = self._forward(obs)
        else:  # equal chunks: 1024 frames in 14 chunks of 74, not 13 of 78 and one of 10
            size = -(-len(obs) // -(-len(obs) // self.chunk))
            out = np.concatenate(
                [self._forward(obs[i : i + size]) for i in range(0, len(obs), size)]
            )
        if not np.isfinite(out).all():
            raise UserError(
                "the policy's outputs are not finite numbers (NaN or inf): it cannot be rolled "
                "out, searched or scored; check its weights"
            )
        return out

    def act(self, obs: np.ndarray) -> np.ndarray:
        """uint8 (B, H, W, 3) -> float32 (B, A), or int64 (B,) argmax for discrete worlds."""
        out = self.outputs(obs)
        return out.argmax(axis=1).astype(np.int64) if self.discrete else out

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.act(obs)

    def fits(self, world) -> None:
        """Raise a one-line UserError unless the policy takes the world's observations and
        gives its kind of actions."""
        if tuple(self.obs_shape) != tuple(world.obs_shape):
            raise UserError(
                f"the policy takes observations of shape {tuple(self.obs_shape)}, but "
                f"{world.name} renders {tuple(world.obs_shape)}"
            )
        if self.discrete != world.discrete or self.action_dim != world.action_dim:
            kind = lambda d, n: f"{n} discrete actions" if d else f"{n}-d continuous actions"  # noqa: E731
            raise UserError(
                f"the policy gives {kind(self.discrete, self.action_dim)}, but {world.name} "
                f"takes {kind(world.discrete, world.action_dim)}"
            )


def probabilities(logits: np.ndarray) -> np.ndarray:
    """Softmax over the last axis, float32."""
    z = logits - logits.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return (e / e.sum(axis=-1, keepdims=True)).astype(np.float32)
