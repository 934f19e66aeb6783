"""The `torch:` policy loader: a PyTorch module the command line names, with its weights.

    load("MODULE:CALLABLE@WEIGHTS.safetensors[#OBS]", world) -> Policy
                                                (registered in policy.loaders as "torch")

CALLABLE() builds a torch.nn.Module; WEIGHTS (a .safetensors file, never a pickle) are its
state. The module takes the world's frames converted as OBS declares (policy.obs.ObsSpec),
wrapped (Converted) so that finetuning trains it on uint8 frames like every other policy.
Whatever the user's module or callable raises (SystemExit included) is one line.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from torch import nn

from policy.model import Origin, Policy
from policy.obs import MAX_WEIGHTS_BYTES, Converted, said, split_obs
from sim.core import UserError

USAGE = "expected torch:MODULE:CALLABLE@WEIGHTS.safetensors"


def module_of(target: str, weights: Path) -> nn.Module:
    """CALLABLE() of "MODULE:CALLABLE", with the state in `weights` loaded into it."""
    module_name, _, attr = target.partition(":")
    if not module_name or not attr:
        raise UserError(f"torch:{target}: {USAGE}")
    try:
        make = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as e:
        raise UserError(f"torch:{target}: cannot find {attr} in {module_name} ({e})") from None
    except (Exception, SystemExit) as e:  # the module's own code failed as it was imported
        raise UserError(f"torch:{target}: importing {module_name} raised {said(e)}") from None
    try:
        net = make()
    except (Exception, SystemExit) as e:
        raise UserError(f"torch:{target}: {attr}() raised {said(e)}") from None
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


def load(target: str, world) -> Policy:
    """The module "MODULE:CALLABLE@WEIGHTS[#OBS]" names, for `world`."""
    spec, obs, tail = split_obs(target)
    where, at, weights = spec.rpartition("@")
    if not at or not where:
        raise UserError(f"torch:{spec}: {USAGE}")
    if not Path(weights).is_file():
        raise UserError(f"torch:{spec}: {weights}: no such file")
    net = Converted(module_of(where, Path(weights)), obs)
    return Policy(
        net,
        discrete=world.discrete,
        obs_shape=world.obs_shape,
        action_dim=world.action_dim,
        source=f"torch:{where}@{Path(weights).resolve()}{tail}",
        origin=Origin.of_file("torch", Path(weights)),
    )
