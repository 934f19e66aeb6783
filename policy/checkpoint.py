"""Checkpoints: `model.safetensors` + `config.json`, written atomically; nothing is unpickled."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from policy.model import ImagePolicy, Policy, PolicyConfig
from sim.core import UserError


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def save_policy(policy: Policy, folder: str | Path, *, meta: dict | None = None) -> Path:
    """Write folder/model.safetensors and folder/config.json (the architecture + `meta`)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().contiguous() for k, v in policy.net.state_dict().items()}
    _atomic_write(folder / "model.safetensors", lambda p: save_file(state, p))
    doc = {"policy": policy.config.to_dict(), "meta": meta or {}}
    _atomic_write(folder / "config.json", lambda p: Path(p).write_text(json.dumps(doc, indent=2)))
    return folder


def load_policy(folder: str | Path, *, world: str | None = None) -> Policy:
    """Load a checkpoint folder; a wrong world, shape or file says so in one line."""
    folder = Path(folder)
    cfg_path, weights = folder / "config.json", folder / "model.safetensors"
    for p in (cfg_path, weights):
        if not p.is_file():
            raise UserError(
                f"checkpoint {folder}: missing {p.name}; expected model.safetensors + config.json"
            )
    try:
        raw = json.loads(cfg_path.read_text())["policy"]
        raw = {k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()}
        config = PolicyConfig(**raw)
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise UserError(f"checkpoint {cfg_path}: malformed config ({e})") from None
    if world is not None and config.world != world:
        raise UserError(f"checkpoint {folder} is for world {config.world!r}, not {world!r}")
    net = ImagePolicy(config)
    try:
        state = load_file(weights)
    except (SafetensorError, OSError) as e:
        raise UserError(f"checkpoint {weights}: not a readable safetensors file ({e})") from None
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
                f"expected {tuple(expected[name].shape)} for obs {config.obs_shape}"
            )
    with torch.no_grad():
        net.load_state_dict(state)
    return Policy(net)
