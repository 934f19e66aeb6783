"""The policy a command names: a checkpoint folder of the project's own, or a policy from outside
loaded by the loader its prefix names (policy.loaders), each as a policy.model.Policy (the one
protocol the search, the loop and the page use). Nothing is ever unpickled.

    load(spec, world, weights=None) -> Policy
        a folder                          the project's own checkpoint (policy.checkpoint)
        onnx:PATH.onnx[#OBS]              an ONNX graph, run by onnxruntime: diagnosis only
                                          (policy.onnx_policy)
        torch:MODULE:CALLABLE@WEIGHTS[#OBS]
                                          CALLABLE() builds a torch.nn.Module, WEIGHTS (a
                                          .safetensors file) are its state: diagnosis and
                                          finetuning (policy.torch_policy)
        sb3:PATH.zip                      a stable-baselines3 PPO, A2C or DQN with CnnPolicy:
                                          diagnosis and finetuning of its policy network
                                          (policy.sb3_policy)
        PREFIX:...                        a loader registered from outside (policy.loaders)
    chosen_policy(world, spec, weights)   that policy, or the world's base policy without a spec

`weights`: a folder of finetuned weights dfa saved for the policy `spec` names (its config.json
records the sha256 of the file the spec reads, never the spec: a folder names no code).

OBS declares the conversion the policy expects of the world's uint8 (B, H, W, 3) frames
(policy.obs.ObsSpec): `chw`, `float`, `scale=X`, `frames=1`. Nothing is guessed: a policy whose
input does not take the converted frames is a one-line error naming both shapes.

A spec "WORD:..." whose WORD is no registered prefix is a checkpoint folder when a folder of
that name exists, else one line naming the accepted prefixes.
"""

from __future__ import annotations

from pathlib import Path

from policy.checkpoint import load_policy
from policy.loaders import PREFIX, is_registered, load_with, unknown
from policy.model import Policy
from policy.obs import ObsSpec
from sim.core import UserError

__all__ = ["ObsSpec", "chosen_policy", "load"]


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
    policy = _load(str(spec), world)
    if weights is None:
        return policy
    return load_policy(Path(weights), world=world, base=policy)


def _load(spec: str, world) -> Policy:
    prefix, sep, target = spec.partition(":")
    if sep and is_registered(prefix):
        return load_with(prefix, target, world)
    if sep and PREFIX.match(prefix) and not Path(spec).exists():
        raise unknown(spec)
    return load_policy(Path(spec), world=world)
