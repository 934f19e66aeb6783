"""The image policy: the paper's CNN trunk (conv 32/64/32, kernels 8/4/3, strides 4/2/1)."""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from sim.core import UserError


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
    kernels: tuple[int, int, int] = (8, 4, 3)
    strides: tuple[int, int, int] = (4, 2, 1)
    hidden: int = 100

    def to_dict(self) -> dict:
        return asdict(self)


class ImagePolicy(nn.Module):
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
        self.trunk = nn.Sequential(*layers, nn.Flatten())
        h, w, _ = config.obs_shape
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
        x = obs.permute(0, 3, 1, 2).float() / 127.5 - 1.0  # (B, 3, H, W) in [-1, 1]
        return self.head(self.trunk(x))


class Policy:
    """A trained ImagePolicy used as a function of numpy observations (no gradients)."""

    def __init__(self, net: ImagePolicy, *, chunk: int = 1024) -> None:
        self.net = net.eval()
        self.config = net.config
        self.chunk = chunk

    def copy(self) -> Policy:
        return Policy(copy.deepcopy(self.net), chunk=self.chunk)

    @torch.inference_mode()
    def outputs(self, obs: np.ndarray) -> np.ndarray:
        """Raw head outputs float32 (B, A): actions, or logits for discrete worlds.

        Raises UserError when any output is not a finite number: nothing downstream (a
        rollout, the search, a success rate) may be computed from one.
        """
        x = torch.from_numpy(np.ascontiguousarray(obs))
        if len(x) <= self.chunk:
            out = self.net(x).numpy()
        else:
            chunks = [self.net(x[i : i + self.chunk]) for i in range(0, len(x), self.chunk)]
            out = torch.cat(chunks).numpy()
        if not np.isfinite(out).all():
            raise UserError(
                "the policy's outputs are not finite numbers (NaN or inf): it cannot be rolled "
                "out, searched or scored; check its weights"
            )
        return out

    def act(self, obs: np.ndarray) -> np.ndarray:
        """uint8 (B, H, W, 3) -> float32 (B, A), or int64 (B,) argmax for discrete worlds."""
        out = self.outputs(obs)
        return out.argmax(axis=1).astype(np.int64) if self.config.discrete else out

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.act(obs)


def probabilities(logits: np.ndarray) -> np.ndarray:
    """Softmax over the last axis, float32."""
    z = logits - logits.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return (e / e.sum(axis=-1, keepdims=True)).astype(np.float32)
