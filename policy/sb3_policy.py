"""The `sb3:` policy loader: a stable-baselines3 PPO, A2C or DQN with CnnPolicy, from its zip.

    load("PATH.zip", world) -> Policy            (registered in policy.loaders as "sb3")

The zip is read without unpickling: `data` is JSON (its ":serialized:" values are never
decoded), `policy.pth` is read as tensors only (torch.load(weights_only=True)), each refused by
its stored inflated size before it is read. The network is rebuilt with stable-baselines3's
own class from the world's spaces and the stored JSON settings, on torch's `meta` device first
so that its shapes are compared with the stored ones before anything is allocated, with the
conversions SB3 applies (VecTransposeImage: channels first; its policies scale pixels by 1/255
themselves). A custom policy class or a policy_kwargs value that only pickle could restore is
a one-line error. The policy's network (SB3Actor) is finetuned like any other, and a finetuned
copy's checkpoint also holds the zip stable-baselines3 opens (policy.sb3zip.save_beside).
"""

from __future__ import annotations

import importlib
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from policy.model import Explainable, Origin, Policy
from policy.obs import MAX_WEIGHTS_BYTES, said, split_obs
from policy.sb3zip import save_beside
from sim.core import UserError

MAX_DATA_BYTES = 64 << 20  # an sb3 zip's `data` (JSON settings) as stored inflated

# the stable-baselines3 policy classes that can be rebuilt: (module, class) -> kind
SB3_CLASSES = {
    ("stable_baselines3.common.policies", "ActorCriticCnnPolicy"): "actor_critic",
    ("stable_baselines3.dqn.policies", "CnnPolicy"): "dqn",
}


class SB3Actor(Explainable):
    """The action scores of a stable-baselines3 policy: PPO/A2C's logits, DQN's Q-values.

    Explainable: SB3 scales pixels by 1/255 itself (preprocess_obs: obs.float() / 255), so
    float frames in [0, 255] give the same scores, differentiable in the pixels; its
    convolutions are those of the features extractor the scores go through (the actor's).
    """

    def __init__(
        self, policy: nn.Module, kind: str, channels_first: bool, frame_shape: tuple[int, int, int]
    ) -> None:
        super().__init__()
        self.policy, self.kind, self.channels_first = policy, kind, channels_first
        self.frame_shape = tuple(frame_shape)  # type: ignore[assignment]

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = obs.permute(0, 3, 1, 2) if self.channels_first else obs  # SB3 scales pixels itself
        if self.kind == "dqn":
            return self.policy.q_net(x)
        p = self.policy
        features = p.extract_features(x, p.pi_features_extractor)
        return p.action_net(p.mlp_extractor.forward_actor(features))

    def pixels(self, obs: torch.Tensor) -> torch.Tensor:
        return self.forward(obs)

    def convolutions(self) -> list[nn.Conv2d]:
        p: Any = self.policy  # an SB3 policy: its extractors are attributes torch cannot type
        extractor = p.q_net.features_extractor if self.kind == "dqn" else p.pi_features_extractor
        return [m for m in extractor.modules() if isinstance(m, nn.Conv2d)]


def _has_pickle(value) -> bool:
    if isinstance(value, dict):
        return ":serialized:" in value or any(_has_pickle(v) for v in value.values())
    if isinstance(value, list):
        return any(_has_pickle(v) for v in value)
    return False


def _sb3_class(data: dict, path: Path) -> tuple[str, str]:
    pc = data.get("policy_class")
    module = pc.get("__module__") if isinstance(pc, dict) else None
    init = pc.get("__init__", "") if isinstance(pc, dict) else ""
    name = init.split(" ")[1].split(".")[0] if init.startswith("<function ") else None
    if (module, name) not in SB3_CLASSES:
        accepted = ", ".join(f"{m}.{c}" for m, c in SB3_CLASSES)
        raise UserError(
            f"{path}: policy class {module}.{name} cannot be rebuilt without unpickling it; "
            f"accepted: {accepted} (CnnPolicy of PPO, A2C or DQN)"
        )
    return module, name


def _read_zip(path: Path) -> tuple[dict, dict[str, torch.Tensor]]:
    """`data` (JSON) and policy.pth (tensors only) of an sb3 zip, each refused by its stored
    inflated size before it is read."""
    limits = {"data": MAX_DATA_BYTES, "policy.pth": MAX_WEIGHTS_BYTES}
    try:
        with zipfile.ZipFile(path) as z:
            for name, limit in limits.items():
                if z.getinfo(name).file_size > limit:
                    raise UserError(
                        f"{path}: its {name} inflates to {z.getinfo(name).file_size >> 20} MiB, "
                        f"over the {limit >> 20} MiB accepted; not read"
                    )
            data = json.loads(z.read("data"))
            with z.open("policy.pth") as f:
                state = torch.load(f, map_location="cpu", weights_only=True)
    except UserError:
        raise
    except (zipfile.BadZipFile, KeyError, OSError, json.JSONDecodeError, RecursionError) as e:
        raise UserError(
            f"{path}: not a stable-baselines3 .zip ({said(e)}); expected data and policy.pth"
        ) from None
    except Exception as e:  # torch.load refusing anything that is not plain tensors
        raise UserError(f"{path}: policy.pth is not plain tensors ({said(e)})") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: its data is JSON {type(data).__name__}, not an object")
    if not isinstance(state, dict) or not all(
        isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items()
    ):
        raise UserError(f"{path}: policy.pth is not a mapping of names to tensors")
    return data, state


def _space(data: dict, key: str, path: Path) -> dict:
    space = data.get(key, {})
    if not isinstance(space, dict):
        raise UserError(f"{path}: its {key} is JSON {type(space).__name__}, not an object")
    return space


def load_sb3(path: Path, world, source: str) -> Policy:
    """The policy network of the sb3 zip at `path`, rebuilt for `world`."""
    data, state = _read_zip(path)
    module, name = _sb3_class(data, path)
    kwargs = data.get("policy_kwargs") or {}
    if not isinstance(kwargs, dict) or _has_pickle(kwargs):
        raise UserError(
            f"{path}: its policy_kwargs hold values only unpickling could restore (a custom "
            "features extractor or activation); rebuild it with plain settings"
        )
    obs_space, act_space = (
        _space(data, "observation_space", path),
        _space(data, "action_space", path),
    )
    raw_shape = obs_space.get("_shape") or ()
    shape = tuple(raw_shape) if isinstance(raw_shape, list) else ()
    h, w, c = world.obs_shape
    channels_first = shape == (c, h, w)
    if shape not in ((c, h, w), (h, w, c)) or obs_space.get("dtype") != "uint8":
        raise UserError(
            f"{path}: the policy takes {str(obs_space.get('dtype'))[:20]} observations of shape "
            f"{shape or str(raw_shape)[:40]}, but {world.name} renders uint8 "
            f"{tuple(world.obs_shape)}"
        )
    n = int(act_space.get("n", -1)) if str(act_space.get("n", "")).isdigit() else -1
    if not world.discrete or n != world.action_dim:
        raise UserError(
            f"{path}: the policy has {n if n > 0 else 'non-discrete'} actions, but {world.name} "
            f"takes {world.action_dim} {'discrete' if world.discrete else 'continuous'} ones"
        )
    import gymnasium

    cls = getattr(importlib.import_module(module), name)
    spaces = (
        gymnasium.spaces.Box(0, 255, shape, np.uint8),
        gymnasium.spaces.Discrete(n),
    )

    def build():
        return cls(*spaces, lr_schedule=lambda _: 0.0, **kwargs)

    try:
        with torch.device("meta"):  # the stored shapes compared before anything is allocated
            shapes = {k: tuple(t.shape) for k, t in build().state_dict().items()}
        stored = {k: tuple(t.shape) for k, t in state.items()}
        if shapes != stored:
            differ = sorted(k for k in set(shapes) | set(stored) if shapes.get(k) != stored.get(k))
            raise UserError(
                f"{path}: policy.pth does not fit the {name} its settings describe (first of "
                f"{len(differ)} differing tensors: {differ[0]}, stored "
                f"{stored.get(differ[0])}, built {shapes.get(differ[0])})"
            )
        policy = build()
        policy.load_state_dict(state)
    except UserError:
        raise
    except (Exception, SystemExit) as e:
        raise UserError(f"{path}: cannot rebuild its {name} ({said(e)})") from None
    kind = SB3_CLASSES[(module, name)]
    net = SB3Actor(policy.eval(), kind, channels_first, world.obs_shape)
    return Policy(net, discrete=True, obs_shape=world.obs_shape, action_dim=n, source=source)


def load(target: str, world) -> Policy:
    """The stable-baselines3 policy of "PATH.zip" for `world`."""
    where, _, tail = split_obs(target)
    if tail:
        raise UserError("sb3: the conversions of a stable-baselines3 policy are its own; drop #...")
    path = Path(where)
    if not path.is_file():
        raise UserError(f"sb3:{where}: no such file")
    policy = load_sb3(path, world, f"sb3:{path.resolve()}")
    policy.origin = Origin.of_file("sb3", path)
    policy.save_beside = save_beside
    return policy
