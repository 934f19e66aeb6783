"""Policies from outside the project, each as a policy.model.Policy (the one protocol the
search, the loop and the page use). Nothing is ever unpickled.

    load(spec, world, weights=None) -> Policy
        a folder                          the project's own checkpoint
        onnx:PATH.onnx[#OBS]              an ONNX graph, run by onnxruntime: diagnosis only
        torch:MODULE:CALLABLE@WEIGHTS[#OBS]
                                          CALLABLE() builds a torch.nn.Module, WEIGHTS (a
                                          .safetensors file) are its state: diagnosis and
                                          finetuning
        sb3:PATH.zip                      a stable-baselines3 PPO, A2C or DQN with CnnPolicy:
                                          diagnosis and finetuning of its policy network

`weights`: a folder of finetuned weights dfa saved for the policy `spec` names (its config.json
records the sha256 of the file the spec reads, never the spec: a folder names no code).

OBS declares the conversion the policy expects of the world's uint8 (B, H, W, 3) frames, as
comma-separated words: `chw` (channels first), `float` (float32), `scale=X` (multiplied by X,
e.g. scale=1/255), `frames=N` (frame stacking: only 1 is supported). Nothing is guessed: a
policy whose input does not take the converted frames is a one-line error naming both shapes.

stable-baselines3 zips are read without unpickling: `data` is JSON (its ":serialized:" values
are never decoded), `policy.pth` is read as tensors only (torch.load(weights_only=True)). The
network is rebuilt with stable-baselines3's own class from the world's spaces and the stored
JSON settings, with the conversions SB3 applies (VecTransposeImage: channels first; its
policies scale pixels by 1/255 themselves). A custom policy class or a policy_kwargs value that
only pickle could restore is a one-line error.
"""

from __future__ import annotations

import importlib
import json
import zipfile
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import torch
from torch import nn

from policy.checkpoint import load_policy
from policy.model import Origin, Policy
from sim.core import UserError, files

MAX_DATA_BYTES = 64 << 20  # an sb3 zip's `data` (JSON settings) as stored inflated
MAX_WEIGHTS_BYTES = 1 << 30  # its policy.pth, and any weights file read whole

# the stable-baselines3 policy classes that can be rebuilt: (module, class) -> kind
SB3_CLASSES = {
    ("stable_baselines3.common.policies", "ActorCriticCnnPolicy"): "actor_critic",
    ("stable_baselines3.dqn.policies", "CnnPolicy"): "dqn",
}


@dataclass(frozen=True)
class ObsSpec:
    """How a policy wants the world's uint8 (B, H, W, 3) frames."""

    channels_first: bool = False
    as_float: bool = False
    scale: float = 1.0
    frames: int = 1

    @classmethod
    def parse(cls, text: str) -> ObsSpec:
        out: dict = {}
        for word in filter(None, (w.strip() for w in text.split(","))):
            key, _, value = word.partition("=")
            try:
                if word == "chw":
                    out["channels_first"] = True
                elif word == "hwc":
                    out["channels_first"] = False
                elif word == "float":
                    out["as_float"] = True
                elif key == "scale" and value:
                    out["scale"], out["as_float"] = float(Fraction(value)), True
                    if not 0 < abs(out["scale"]) < float("inf"):
                        raise ValueError
                elif key == "frames" and value:
                    out["frames"] = int(value)
                else:
                    raise ValueError
            except (ValueError, ZeroDivisionError, OverflowError):
                raise UserError(
                    f"observation option {word[:40]!r}: accepted: chw, hwc, float, scale=X "
                    "(a finite non-zero number, e.g. scale=1/255), frames=1"
                ) from None
        spec = cls(**out)
        if spec.frames != 1:
            raise UserError(
                f"frames={spec.frames}: frame-stacked policies are not supported (a policy "
                "here sees one frame per step)"
            )
        return spec

    def shape(self, obs_shape: tuple[int, int, int]) -> tuple[int, int, int]:
        h, w, c = obs_shape
        return (c, h, w) if self.channels_first else (h, w, c)

    def convert(self, obs: torch.Tensor) -> torch.Tensor:
        """uint8 (B, H, W, 3) -> what the policy takes."""
        x = obs.permute(0, 3, 1, 2) if self.channels_first else obs
        if self.as_float:
            x = x.float() * self.scale
        return x.contiguous()


class Converted(nn.Module):
    """A module that takes converted frames, as one that takes the world's uint8 frames."""

    def __init__(self, module: nn.Module, obs: ObsSpec) -> None:
        super().__init__()
        self.module, self.obs = module, obs

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.module(self.obs.convert(obs))


def _probe(policy: Policy, world) -> Policy:
    """Run the policy on one of the world's frames: a wrong input or output shape is one line."""
    frame = world.render(world.sample_scene(0))[None]  # (1, H, W, 3)
    try:
        out = policy.outputs(frame)
    except UserError:
        raise
    except Exception as e:  # the module's own complaint about its input
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise UserError(
            f"the policy does not take {world.name}'s frames {tuple(world.obs_shape)} "
            f"converted to {_converted_shape(policy, world)}: {first[:160]}"
        ) from None
    if out.shape != (1, world.action_dim):
        what = "action scores" if world.discrete else "action components"
        raise UserError(
            f"the policy gives outputs of shape {tuple(out.shape[1:])} per frame, but "
            f"{world.name} needs {world.action_dim} {what}"
        )
    return policy


def _converted_shape(policy: Policy, world) -> tuple[int, ...]:
    obs = getattr(policy, "obs", None) or getattr(policy.net, "obs", None) or ObsSpec()
    return obs.shape(world.obs_shape)


# -- ONNX ---------------------------------------------------------------------------------------
class OnnxPolicy(Policy):
    """An ONNX graph run by onnxruntime on the CPU (it cannot be finetuned: net is None)."""

    def __init__(self, path: Path, world, obs: ObsSpec, source: str) -> None:
        import onnxruntime

        try:
            options = onnxruntime.SessionOptions()
            options.log_severity_level = 3  # errors only: its warnings are not ours to print
            self.session = onnxruntime.InferenceSession(
                str(path), options, providers=["CPUExecutionProvider"]
            )
        except Exception as e:
            raise UserError(
                f"{path}: not a readable ONNX model ({str(e).splitlines()[0][:120]})"
            ) from None
        inputs = self.session.get_inputs()
        if len(inputs) != 1:
            raise UserError(
                f"{path}: the graph takes {len(inputs)} inputs; a policy takes one (the frame)"
            )
        self.input = inputs[0]
        self.obs = obs
        want = obs.shape(world.obs_shape)
        got = tuple(self.input.shape[1:])
        if len(got) != 3 or any(
            isinstance(g, int) and g != w for g, w in zip(got, want, strict=True)
        ):
            raise UserError(
                f"{path}: the graph takes frames of shape {got}, but {world.name}'s frames "
                f"{tuple(world.obs_shape)} converted as declared give {want}"
            )
        out = self.session.get_outputs()[0]  # as onnxruntime infers it from the graph
        dims = list(out.shape)
        free_batch = len(dims) == 2 and (dims[0] == 1 or not isinstance(dims[0], int))
        if not free_batch or dims[1] != world.action_dim:
            raise UserError(
                f"{path}: the graph's output {out.name!r} has shape {dims}; a policy gives "
                f"(batch, {world.action_dim}) for {world.name}, with the {world.action_dim} fixed"
            )
        wants_float = self.input.type == "tensor(float)"
        if wants_float != obs.as_float:
            raise UserError(
                f"{path}: the graph takes {self.input.type}, but the declared conversion gives "
                f"{'float' if obs.as_float else 'uint8'}; declare #float (and scale=...) or not"
            )
        super().__init__(
            None,
            discrete=world.discrete,
            obs_shape=world.obs_shape,
            action_dim=world.action_dim,
            source=source,
        )

    def _forward(self, obs: np.ndarray) -> np.ndarray:
        x = self.obs.convert(torch.from_numpy(np.ascontiguousarray(obs))).numpy()
        return np.asarray(self.session.run(None, {self.input.name: x})[0], np.float32)


# -- PyTorch modules ----------------------------------------------------------------------------
def _torch_module(target: str, weights: Path) -> nn.Module:
    module_name, _, attr = target.partition(":")
    if not module_name or not attr:
        raise UserError(f"torch:{target}: expected torch:MODULE:CALLABLE@WEIGHTS.safetensors")
    try:
        make = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as e:
        raise UserError(f"torch:{target}: cannot find {attr} in {module_name} ({e})") from None
    except (Exception, SystemExit) as e:  # the module's own code failed as it was imported
        raise UserError(f"torch:{target}: importing {module_name} raised {_said(e)}") from None
    try:
        net = make()
    except (Exception, SystemExit) as e:
        raise UserError(f"torch:{target}: {attr}() raised {_said(e)}") from None
    if not isinstance(net, nn.Module):
        raise UserError(
            f"torch:{target}: {attr}() gave a {type(net).__name__}, not a torch.nn.Module"
        )
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    if weights.stat().st_size > MAX_WEIGHTS_BYTES:
        raise UserError(f"{weights}: over {MAX_WEIGHTS_BYTES >> 20} MiB; not read")
    try:
        state = load_file(str(weights))
    except (SafetensorError, OSError) as e:
        raise UserError(f"{weights}: not a readable safetensors file ({e})") from None
    try:
        net.load_state_dict(state)
    except RuntimeError as e:
        raise UserError(
            f"{weights}: does not fit {attr}(): {str(e).splitlines()[0][:160]}"
        ) from None
    return net


def _said(e: BaseException) -> str:
    """An exception as a few words on one line."""
    text = str(e).strip().splitlines()[0][:160] if str(e).strip() else ""
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


# -- stable-baselines3 --------------------------------------------------------------------------
class SB3Actor(nn.Module):
    """The action scores of a stable-baselines3 policy: PPO/A2C's logits, DQN's Q-values."""

    def __init__(self, policy: nn.Module, kind: str, channels_first: bool) -> None:
        super().__init__()
        self.policy, self.kind, self.channels_first = policy, kind, channels_first

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = obs.permute(0, 3, 1, 2) if self.channels_first else obs  # SB3 scales pixels itself
        if self.kind == "dqn":
            return self.policy.q_net(x)
        p = self.policy
        features = p.extract_features(x, p.pi_features_extractor)
        return p.action_net(p.mlp_extractor.forward_actor(features))


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
            f"{path}: not a stable-baselines3 .zip ({_said(e)}); expected data and policy.pth"
        ) from None
    except Exception as e:  # torch.load refusing anything that is not plain tensors
        raise UserError(f"{path}: policy.pth is not plain tensors ({_said(e)})") from None
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
        raise UserError(f"{path}: cannot rebuild its {name} ({_said(e)})") from None
    kind = SB3_CLASSES[(module, name)]
    net = SB3Actor(policy.eval(), kind, channels_first)
    return Policy(net, discrete=True, obs_shape=world.obs_shape, action_dim=n, source=source)


# -- the dispatch -------------------------------------------------------------------------------
def _origin(kind: str, path: Path) -> Origin:
    return Origin(kind, path.name, files.sha256(path))


def chosen_policy(world, spec: str | None, weights: str | Path | None = None) -> Policy:
    """The policy a command diagnoses: the one `spec` names (with finetuned `weights`), else
    the world's base policy; checked to fit `world`."""
    from policy.base import base_policy

    if spec is None:
        if weights is not None:
            raise UserError(
                f"--weights {weights}: finetuned weights go with the --policy they were "
                "finetuned from; give that too (or give a checkpoint folder of the project's "
                "own as --policy)"
            )
        policy = base_policy(world)
    else:
        policy = load(spec, world, weights=weights)
    policy.fits(world)
    return policy


def load(spec: str, world, *, weights: str | Path | None = None) -> Policy:
    """The policy `spec` names, checked to fit `world` (see the module docstring); with
    `weights`, that policy with the finetuned weights dfa saved for it."""
    policy = _load(spec, world)
    if weights is None:
        return policy
    return load_policy(Path(weights), world=world, base=policy)


def _load(spec: str, world) -> Policy:
    kind, sep, rest = str(spec).partition(":")
    if not sep or kind not in ("onnx", "torch", "sb3"):
        return load_policy(Path(spec), world=world)
    target, _, obs_text = rest.partition("#")
    obs = ObsSpec.parse(obs_text)
    tail = f"#{obs_text}" if obs_text else ""  # a source names its files by absolute paths
    if kind == "onnx":
        path = Path(target)
        if not path.is_file():
            raise UserError(f"onnx:{target}: no such file")
        policy = OnnxPolicy(path, world, obs, f"onnx:{path.resolve()}{tail}")
        policy.origin = _origin("onnx", path)
        return _probe(policy, world)
    if kind == "torch":
        where, at, weights = target.rpartition("@")
        if not at or not where:
            raise UserError(f"torch:{target}: expected torch:MODULE:CALLABLE@WEIGHTS.safetensors")
        if not Path(weights).is_file():
            raise UserError(f"torch:{target}: {weights}: no such file")
        net = Converted(_torch_module(where, Path(weights)), obs)
        policy = Policy(
            net,
            discrete=world.discrete,
            obs_shape=world.obs_shape,
            action_dim=world.action_dim,
            source=f"torch:{where}@{Path(weights).resolve()}{tail}",
            origin=_origin("torch", Path(weights)),
        )
        return _probe(policy, world)
    if obs_text:
        raise UserError("sb3: the conversions of a stable-baselines3 policy are its own; drop #...")
    path = Path(target)
    if not path.is_file():
        raise UserError(f"sb3:{target}: no such file")
    policy = load_sb3(path, world, f"sb3:{path.resolve()}")
    policy.origin = _origin("sb3", path)
    return _probe(policy, world)
