"""The `onnx:` policy loader: an ONNX graph run by onnxruntime on the CPU, for diagnosis only.

    load("PATH.onnx[#OBS]", world) -> OnnxPolicy     (registered in policy.loaders as "onnx")

The graph takes one input, the frame converted as OBS declares (policy.obs.ObsSpec), and gives
(batch, A) with A the world's action size, fixed: both are checked, as onnxruntime infers them
from the graph, before it is run. It cannot be finetuned (its `net` is None).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from policy.model import Origin, Policy
from policy.obs import ObsSpec, split_obs
from sim.core import UserError


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


def load(target: str, world) -> Policy:
    """The graph of "PATH.onnx[#OBS]" for `world`; anything wrong with it is one line."""
    where, obs, tail = split_obs(target)
    path = Path(where)
    if not path.is_file():
        raise UserError(f"onnx:{where}: no such file")
    policy = OnnxPolicy(path, world, obs, f"onnx:{path.resolve()}{tail}")
    policy.origin = Origin.of_file("onnx", path)
    return policy
