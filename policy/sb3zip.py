"""stable-baselines3 zips that stable-baselines3's own `PPO.load` (A2C.load, DQN.load) opens,
written from one it opened before; nothing is unpickled.

An SB3 zip holds `data` (JSON settings), `policy.pth` (the policy's state dict),
`policy.optimizer.pth` (its optimizer's state dict), `pytorch_variables.pth`,
`_stable_baselines3_version` and `system_info.txt`. `PPO.load` refuses a zip without
`policy.optimizer.pth` (KeyError 'policy.optimizer'), so a zip written here always has one:
the original's, or a fresh optimizer's (its settings, no running averages: what a model that
has not trained yet holds).

    members(path)                       the zip's members as bytes, in order (read, not loaded)
    fresh_optimizer(sb3_policy, data)   a fresh optimizer's state dict (data's learning rate)
    with_optimizer(path, sb3_policy)    add a fresh optimizer to a zip that lacks one
    export_finetuned(policy, path)      the policy's original zip, its policy.pth replaced by
                                        the finetuned state dict (SB3's own key names)
    save_beside(policy, folder)         export_finetuned to folder/sb3.zip: what a checkpoint
                                        of a finetuned sb3 policy holds besides its weights
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import torch
from torch import nn

from sim.core import UserError, files

OPTIMIZER = "policy.optimizer.pth"
SB3_ZIP = "sb3.zip"  # a finetuned stable-baselines3 policy, as stable-baselines3 stores one
WEIGHTS = "policy.pth"
MAX_MEMBERS_BYTES = 1 << 30  # an sb3 zip copied here, inflated


def members(path: str | Path) -> dict[str, bytes]:
    """Every member of an sb3 zip as bytes, in the zip's order; nothing is loaded from them."""
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            if sum(i.file_size for i in infos) > MAX_MEMBERS_BYTES:
                raise UserError(f"{path}: inflates to over {MAX_MEMBERS_BYTES >> 20} MiB")
            out = {i.filename: z.read(i) for i in infos}
    except (zipfile.BadZipFile, OSError) as e:
        raise UserError(f"{path}: not a readable .zip ({type(e).__name__}: {e})") from None
    if "data" not in out or WEIGHTS not in out:
        raise UserError(f"{path}: not a stable-baselines3 .zip; expected data and {WEIGHTS}")
    return out


def tensor_bytes(obj) -> bytes:
    """`obj` (a state dict) as torch.save writes it, the way stable-baselines3 stores it."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def fresh_optimizer(sb3_policy: nn.Module, data: bytes) -> dict:
    """The state dict of `sb3_policy`'s optimizer as built (its class's settings, no running
    averages), with the learning rate `data` (the zip's JSON) records when it is a number."""
    optimizer = getattr(sb3_policy, "optimizer", None)
    if not isinstance(optimizer, torch.optim.Optimizer):
        raise UserError("the stable-baselines3 policy has no optimizer to describe")
    state = optimizer.state_dict()
    lr = json.loads(data).get("learning_rate")
    groups = [
        dict(g, lr=float(lr)) if isinstance(lr, int | float) and not isinstance(lr, bool) else g
        for g in state["param_groups"]
    ]
    return {"state": {}, "param_groups": groups}


def write_zip(path: str | Path, contents: dict[str, bytes], *, like: str | Path) -> Path:
    """Write `contents` as a zip atomically, each member stored as in `like` (its date and
    compression); a member `like` lacks is stored as its first one."""
    with zipfile.ZipFile(like) as z:
        infos = {i.filename: i for i in z.infolist()}
    first = next(iter(infos.values()))
    with files.atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w") as out:
        for name, data in contents.items():
            old = infos.get(name, first)
            info = zipfile.ZipInfo(name, date_time=old.date_time)
            info.compress_type, info.external_attr = old.compress_type, old.external_attr
            out.writestr(info, data)
    return Path(path)


def with_optimizer(path: str | Path, sb3_policy: nn.Module) -> bool:
    """Add a fresh optimizer's state (fresh_optimizer) to the zip at `path` when it has none,
    leaving every other member's bytes as they are; True when it was added."""
    contents = members(path)
    if OPTIMIZER in contents:
        return False
    with files.atomic_path(path) as tmp:
        tmp.write_bytes(Path(path).read_bytes())
        with zipfile.ZipFile(tmp, "a") as z:
            first = z.infolist()[0]
            info = zipfile.ZipInfo(OPTIMIZER, date_time=first.date_time)
            info.compress_type, info.external_attr = first.compress_type, first.external_attr
            z.writestr(info, tensor_bytes(fresh_optimizer(sb3_policy, contents["data"])))
    return True


def export_finetuned(policy, path: str | Path) -> Path | None:
    """Write `policy` (a finetuned copy of an sb3 policy: source "sb3:PATH", origin its sha256)
    as an SB3 zip at `path`: the original zip's members with policy.pth replaced by the
    finetuned state dict under SB3's own key names, and a fresh optimizer where the original
    has none. None (nothing written) when the original file is gone or no longer the one the
    policy was loaded from: the zip is made from that file only."""
    origin, source = policy.origin, policy.source or ""
    original = Path(source.removeprefix("sb3:"))
    if origin is None or origin.kind != "sb3" or not source.startswith("sb3:"):
        raise UserError(f"{source or 'this policy'}: not a stable-baselines3 policy")
    if not original.is_file() or files.sha256(original) != origin.sha256:
        return None
    sb3_policy = policy.net.policy  # policy.sb3_policy.SB3Actor: the SB3 policy module it runs
    contents = members(original)
    contents[WEIGHTS] = tensor_bytes(sb3_policy.state_dict())
    if OPTIMIZER not in contents:
        contents[OPTIMIZER] = tensor_bytes(fresh_optimizer(sb3_policy, contents["data"]))
    return write_zip(path, contents, like=original)


def save_beside(policy, folder: str | Path) -> Path | None:
    """export_finetuned(policy, folder/sb3.zip): the sb3 loader's Policy.save_beside, which
    save_policy calls once the checkpoint is written."""
    return export_finetuned(policy, Path(folder) / SB3_ZIP)
