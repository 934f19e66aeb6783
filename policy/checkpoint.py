"""Checkpoints: `model.safetensors` + `config.json`, written atomically; nothing is unpickled.

A checkpoint is checked before anything is built from it: config.json must be UTF-8 JSON whose
architecture is in range and fits the world (observation shape, action size and kind), and
every tensor must have the architecture's shape and finite values.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import load_file, save_file

from policy.model import HEADS, ImagePolicy, Origin, Policy, PolicyConfig
from sim.core import UserError, World, files

# what a checkpoint's architecture may ask for: (field, smallest, largest) for each integer
BOUNDS = {"channels": (1, 256), "kernels": (1, 16), "strides": (1, 8), "hidden": (1, 4096)}
MAX_SIDE_PX = 1024  # observations up to 1024 x 1024 pixels
MAX_ACTIONS = 256
WEIGHTS = "model.safetensors"


def save_policy(policy: Policy, folder: str | Path, *, meta: dict | None = None) -> Path:
    """Write folder/model.safetensors and folder/config.json: the architecture (or, for a
    policy from outside, its Origin: what it was loaded from, as data), the weights' sha256 and
    `meta`. The weights are written first: a crash between the two leaves a digest that does
    not match, never a folder that loads as something it is not. Then the policy's loader
    writes what it keeps beside them (`policy.save_beside`: for a finetuned stable-baselines3
    policy, folder/sb3.zip, which stable-baselines3's own load opens, made from the zip the
    policy was loaded from when that file is still there and unchanged)."""
    if policy.net is None:
        raise UserError("this policy has no weights of its own to save (an ONNX graph)")
    if policy.source is not None and policy.origin is None:
        raise UserError(f"{policy.source}: its loader recorded no origin; it cannot be saved")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    state, aliases = unique_tensors(policy.net.state_dict())
    with files.atomic_path(folder / WEIGHTS) as tmp:
        save_file(state, str(tmp), metadata={"aliases": json.dumps(aliases)} if aliases else None)
        digest = files.sha256(tmp)
    if policy.origin is None:
        doc = {"policy": policy.config.to_dict()}
    else:
        doc = {"origin": policy.origin.to_dict()}
    doc |= {"weights_sha256": digest, "meta": meta or {}}
    files.write_text(folder / "config.json", json.dumps(doc, indent=2) + "\n")
    if policy.save_beside is not None:
        policy.save_beside(policy, folder)
    return folder


def unique_tensors(
    state: dict[str, torch.Tensor],
) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """A state dict with each shared tensor once (e.g. stable-baselines3's actor and critic
    share one features extractor), and {alias: the name it is stored under}."""
    kept: dict[tuple, str] = {}
    unique: dict[str, torch.Tensor] = {}
    aliases: dict[str, str] = {}
    for name, t in state.items():
        key = (t.untyped_storage().data_ptr(), t.storage_offset(), tuple(t.shape), t.stride())
        if key in kept:
            aliases[name] = kept[key]
        else:
            kept[key] = name
            unique[name] = t.detach().contiguous()
    return unique, aliases


def _read_tensors(weights: Path) -> dict[str, torch.Tensor]:
    """Every tensor of a model.safetensors, the shared ones under each of their names."""
    try:
        state = load_file(weights)
        with safe_open(weights, "pt") as f:
            meta = f.metadata() or {}
    except (SafetensorError, OSError) as e:
        raise UserError(f"checkpoint {weights}: not a readable safetensors file ({e})") from None
    try:
        aliases = json.loads(meta.get("aliases", "{}"))
        ok = isinstance(aliases, dict) and all(
            isinstance(a, str) and isinstance(k, str) and k in state for a, k in aliases.items()
        )
    except (json.JSONDecodeError, RecursionError):
        ok = False
    if not ok:
        raise UserError(
            f"checkpoint {weights}: its 'aliases' metadata is not a JSON object naming stored "
            "tensors"
        )
    return state | {alias: state[name] for alias, name in aliases.items()}


def read_config(folder: str | Path) -> dict[str, Any]:
    """The parsed config.json of a checkpoint folder (UserError when it is missing or not a
    JSON object)."""
    path = Path(folder) / "config.json"
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise UserError(
            f"checkpoint {folder}: missing config.json; expected model.safetensors + config.json"
        ) from None
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        why = "not UTF-8 text" if isinstance(e, UnicodeDecodeError) else "not valid JSON"
        raise UserError(f"checkpoint {path}: {why}; expected a JSON object") from None
    kinds = ("policy", "origin")
    if not isinstance(doc, dict) or not any(isinstance(doc.get(k), dict) for k in kinds):
        if isinstance(doc, dict) and isinstance(doc.get("source"), str):
            return doc  # an older finetuned copy of an outside policy: see load_policy
        raise UserError(
            f'checkpoint {path}: expected a JSON object with a "policy" object '
            "(world, obs_shape, action_dim, discrete, channels, kernels, strides, hidden[, head]) "
            'or an "origin" object (kind, file, sha256: the policy from outside it was finetuned '
            "from)"
        )
    return doc


def _origin(folder: Path, raw: Any) -> Origin:
    """The "origin" of a finetuned copy of an outside policy, checked to be plain data."""
    fields = ("kind", "file", "sha256")
    if not (
        isinstance(raw, dict)
        and set(raw) == set(fields)
        and all(isinstance(raw[k], str) and 0 < len(raw[k]) <= 255 for k in fields)
        and _is_sha256(raw["sha256"])
    ):
        raise UserError(
            f"checkpoint {folder / 'config.json'}: origin must be an object of kind, file and "
            "sha256 (64 hex digits), all strings"
        )
    return Origin(raw["kind"], raw["file"], raw["sha256"])


def _is_sha256(text: Any) -> bool:
    return isinstance(text, str) and len(text) == 64 and all(c in HEX for c in text)


HEX = frozenset("0123456789abcdef")


def _ints(path: Path, name: str, value: Any, n: int | None, lo: int, hi: int) -> tuple[int, ...]:
    """`value` as n integers in [lo, hi] (one integer when n is None), else a UserError."""
    items = [value] if n is None else value
    ok = (n is None or (isinstance(value, list) and len(value) == n)) and all(
        isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi for v in items
    )
    if not ok:
        what = "an integer" if n is None else f"a list of {n} integers"
        raise UserError(
            f"checkpoint {path}: {name} must be {what} from {lo} to {hi}, not {json.dumps(value)}"
        )
    return tuple(items)


def config_for(folder: str | Path, world: World) -> PolicyConfig:
    """The architecture in a checkpoint's config.json, checked against `world`."""
    path = Path(folder) / "config.json"
    raw = read_config(folder)["policy"]
    head = raw.get("head", "flatten")  # absent: the paper's (configs written before heads)
    if head not in HEADS:
        raise UserError(
            f"checkpoint {path}: head must be one of {', '.join(HEADS)}, not {json.dumps(head)}"
        )
    defaults = PolicyConfig(
        world.name, world.obs_shape, world.action_dim, world.discrete, head=head
    )
    if raw.get("world") != world.name:
        raise UserError(
            f"checkpoint {folder} is for world {json.dumps(raw.get('world'))}, not {world.name!r}"
        )
    obs = _ints(path, "obs_shape", raw.get("obs_shape"), 3, 1, MAX_SIDE_PX)
    if obs != world.obs_shape:
        raise UserError(
            f"checkpoint {path}: obs_shape {list(obs)} does not fit {world.name}, whose "
            f"observations are {list(world.obs_shape)}"
        )
    action_dim = _ints(path, "action_dim", raw.get("action_dim"), None, 1, MAX_ACTIONS)[0]
    discrete = raw.get("discrete")
    if discrete is not world.discrete or action_dim != world.action_dim:
        kind = f"{world.action_dim} discrete actions" if world.discrete else "continuous"
        raise UserError(
            f"checkpoint {path}: discrete={json.dumps(discrete)}, action_dim={action_dim} does "
            f"not fit {world.name} ({kind}, action_dim {world.action_dim})"
        )
    arch: dict[str, Any] = {}
    for name, (lo, hi) in BOUNDS.items():
        value = raw.get(name, getattr(defaults, name))
        if isinstance(value, tuple):
            value = list(value)
        arch[name] = _ints(path, name, value, None if name == "hidden" else 3, lo, hi)
    arch["hidden"] = arch["hidden"][0]
    extra = sorted(set(raw) - {"world", "obs_shape", "action_dim", "discrete", "head", *BOUNDS})
    if extra:
        raise UserError(f"checkpoint {path}: unknown fields {extra}")
    side = min(obs[:2])
    for k, s in zip(arch["kernels"], arch["strides"], strict=True):
        side = (side - k) // s + 1
        if side < 1:
            raise UserError(
                f"checkpoint {path}: kernels {list(arch['kernels'])} and strides "
                f"{list(arch['strides'])} do not fit {obs[0]}x{obs[1]} observations"
            )
    return PolicyConfig(world.name, obs, action_dim, world.discrete, head=head, **arch)


def check_weights(folder: Path, doc: dict) -> None:
    """The weights are what config.json says they were: its "weights_sha256" (written by
    save_policy; absent in folders written before it was recorded) against the file."""
    want = doc.get("weights_sha256")
    if want is None:
        return
    if not _is_sha256(want):
        raise UserError(
            f"checkpoint {folder / 'config.json'}: weights_sha256 must be 64 hex digits"
        )
    if files.sha256(folder / WEIGHTS) != want:
        raise UserError(
            f"checkpoint {folder}: {WEIGHTS} is not the file config.json recorded (its sha256 "
            "differs): it was changed or damaged after it was saved"
        )


def load_policy(folder: str | Path, *, world: World, base: Policy | None = None) -> Policy:
    """Load a checkpoint folder for `world`; anything wrong with it is one UserError line.

    A folder names no code: the project's own checkpoint holds its architecture; a finetuned
    copy of a policy from outside holds only its Origin, and is loaded as new weights for
    `base`, the same policy given again by the user (its file's sha256 must match)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"checkpoint {folder}: not a folder; expected model.safetensors + config")
    weights = folder / WEIGHTS
    if not weights.is_file():
        raise UserError(
            f"checkpoint {folder}: missing model.safetensors; expected model.safetensors + "
            "config.json"
        )
    doc = read_config(folder)
    check_weights(folder, doc)
    if "policy" in doc:
        if base is not None and base.source is not None:
            raise UserError(
                f"checkpoint {folder} holds a policy of its own (its architecture is in its "
                f"config.json), not weights for {base.source}; give it alone with --policy"
            )
        policy = Policy(ImagePolicy(config_for(folder, world)))
    else:
        policy = _outside_base(folder, doc, base)
    net = policy.net
    state = _read_tensors(weights)
    expected = net.state_dict()
    if set(state) != set(expected):
        raise UserError(
            f"checkpoint {weights}: tensors {sorted(set(state) ^ set(expected))} do not match "
            f"the architecture in config.json"
        )
    for name, t in state.items():
        if t.shape != expected[name].shape:
            raise UserError(
                f"checkpoint {weights}: tensor {name} has shape {tuple(t.shape)}, "
                f"expected {tuple(expected[name].shape)} for obs {world.obs_shape}"
            )
        if not torch.isfinite(t).all():
            bad = int((~torch.isfinite(t)).sum())
            raise UserError(f"checkpoint {weights}: tensor {name} has {bad} non-finite values")
    with torch.no_grad():
        net.load_state_dict(state)
    return policy


def _outside_base(folder: Path, doc: dict, base: Policy | None) -> Policy:
    """A copy of `base` to load a finetuned copy's weights into, once `base` is shown to be
    the policy the folder was finetuned from."""
    if "origin" in doc:
        origin = _origin(folder, doc["origin"])
        if base is None or base.source is None:
            raise UserError(
                f"checkpoint {folder} holds finetuned weights of {origin}; it is loaded only "
                f"beside that policy: give it with --policy and this folder with --weights"
            )
        if base.origin != origin:
            raise UserError(
                f"checkpoint {folder} holds finetuned weights of {origin}, not of "
                f"{base.origin or base.source}"
            )
    elif base is None or base.source != doc["source"]:  # written before origins were recorded
        raise UserError(
            f"checkpoint {folder} names the policy it was finetuned from by a spec "
            f"({json.dumps(doc['source'])[:80]}), which dfa does not follow; give that policy "
            "with --policy and this folder with --weights"
        )
    if base.net is None:
        raise UserError(f"checkpoint {folder}: {base.source} has no weights to load into")
    return base.copy()
