"""Saliency maps of a policy's frames, by captum: where in a frame its output comes from.

What is explained, per frame t of a rollout: for continuous actions the closeness of the
policy's action to the demonstration's, -||pi(s_t) - a_t||_2; for discrete actions the logit
of the demonstrated action a_t. Every map is a non-negative density over the frame's pixels,
float32 (T, H, W): the attribution of a region is its sum over the region's pixels.

  integrated_gradients  captum IntegratedGradients from a black frame, 32 Gauss-Legendre steps;
                        |attribution| summed over the colour channels
  occlusion             captum Occlusion: a black k x k patch, k = max(3, H // 12) pixels, slid
                        in strides of max(1, k // 2); |attribution| summed over the channels
  grad_cam              captum LayerGradCam on the trunk's last convolution whose output has
                        more than one cell (on 36x36 frames the last one's output is 1x1,
                        which would make Grad-CAM one number per frame: there it is the second,
                        3x3), upsampled bilinearly to the frame; its magnitude (the original
                        ReLU keeps what raises the explained number, and a failure's cause
                        lowers it), like every other method's
  kernel_shap           captum KernelShap with one feature per object (its pixels,
                        sim.core.visible.slot_masks) and one for the rest of the frame, a
                        feature turned off to black; 64 coalitions, fitted by exact weighted
                        least squares; |Shapley value| of a feature spread evenly over its pixels

`attributions` keeps the sign beside: the same methods' attribution summed over the colour
channels without abs() (Grad-CAM's map and KernelSHAP's values as they are), positive where a
pixel raises the explained number (pulls the action towards the demonstration), negative where
it pushes it away. `attribute` is the unsigned density alone.

Only a network that declares what the methods need can be explained (policy.model.Explainable:
its outputs from float frames, differentiable in the pixels, and its convolutions): the
project's own image policies and outside stable-baselines3 CNN policies (policy.sb3_policy).
The methods take gradients of, or perturb, float frames. A non-finite attribution is refused
(UserError).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from policy.methods import METHODS, check_method  # noqa: F401 (study.protocol reads METHODS here)
from policy.model import Explainable, Policy
from sim.core import Trajectory, UserError, World


@dataclass(frozen=True)
class SaliencyConfig:
    """How each method is run."""

    ig_steps: int = 32
    """Integrated Gradients: steps of the path integral from the black frame."""
    occlusion_px: int | None = None
    """Occlusion: the patch's side in pixels (None: max(3, H // 12))."""
    shap_samples: int = 64
    """KernelSHAP: coalitions sampled per frame (the empty and the full one always)."""
    batch: int = 512
    """Frames per forward pass inside the methods."""


def live_steps(world: World, traj: Trajectory) -> int:
    """The steps a trajectory took before its episode ended (`world.done`): a rollout runs to
    the horizon, and once an episode ends its steps repeat the last frame and action."""
    return next((t for t, s in enumerate(traj.scenes) if world.done(s)), traj.horizon)


def explained_steps(world: World, rollout: Trajectory, demo: Trajectory) -> int:
    """The steps of a rollout that have a demonstrated action to explain against: those before
    either episode ended (at least the first)."""
    return max(1, min(live_steps(world, rollout), live_steps(world, demo)))


def saliency_maps(
    world: World,
    policy: Policy,
    rollout: Trajectory,
    demo: Trajectory,
    method: str,
    *,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> np.ndarray:
    """float32 (T, H, W) in [0, 1]: one map per step of `rollout` that `demo` has an action for
    (T = explained_steps: the steps before either episode ended), divided by the largest value
    over the whole rollout (all zeros stay zeros), so that maps of one rollout compare across
    steps. For an overlay on the rollout's frames 0 .. T-1."""
    check_method(method)
    steps = explained_steps(world, rollout, demo)
    obs = rollout.observations[:steps]  # (T, H, W, 3) uint8
    features = None
    if method == "kernel_shap":
        from sim.core.visible import slot_masks

        features = feature_labels(slot_masks(world, list(rollout.scenes[:steps])))
    maps = attribute(
        policy,
        obs,
        demo.actions[:steps],
        method,
        features=features,
        seed=seed,
        config=config,
    )
    top = float(maps.max()) if maps.size else 0.0
    return (maps / top if top > 0 else maps).astype(np.float32)


def feature_labels(masks: np.ndarray) -> np.ndarray:
    """int64 (T, H, W) of bool masks (T, S, H, W): 0 for pixels of no object, s + 1 for the
    pixels of slot s (the first slot where masks overlap)."""
    t, s, h, w = masks.shape
    labels = np.zeros((t, h, w), np.int64)
    for j in reversed(range(s)):
        labels[masks[:, j]] = j + 1
    return labels


def attribute(
    policy: Policy,
    obs: np.ndarray,
    demo_actions: np.ndarray,
    method: str,
    *,
    features: np.ndarray | None = None,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> np.ndarray:
    """float32 (T, H, W) >= 0: the attribution density of each frame.

    obs: uint8 (T, H, W, 3) frames; demo_actions: float32 (T, A) or int64 (T,) the actions the
    policy is explained against; features: int64 (T, H, W) object labels (kernel_shap only;
    feature_labels). Runs with gradients on whatever torch threads are set.
    """
    return attributions(
        policy, obs, demo_actions, method, features=features, seed=seed, config=config
    )[0]


def attributions(
    policy: Policy,
    obs: np.ndarray,
    demo_actions: np.ndarray,
    method: str,
    *,
    features: np.ndarray | None = None,
    seed: int = 0,
    config: SaliencyConfig = SaliencyConfig(),
) -> tuple[np.ndarray, np.ndarray]:
    """(unsigned, signed), float32 (T, H, W) each, from one run of the method: the density
    `attribute` returns (>= 0), and the signed attribution per pixel (negative: the pixel
    pushes the policy's output away from the demonstrated action). Arguments as `attribute`."""
    check_method(method)
    net = _image_net(policy)
    obs = np.asarray(obs)
    assert obs.dtype == np.uint8 and obs.ndim == 4 and obs.shape[1:] == policy.obs_shape, (
        f"expected uint8 (T, {', '.join(map(str, policy.obs_shape))}), got {obs.dtype} {obs.shape}"
    )
    assert len(demo_actions) == len(obs), "one demonstrated action per frame"
    if len(obs) == 0:
        empty = np.zeros(obs.shape[:3], np.float32)
        return empty, empty.copy()
    model = _Explained(net, policy.discrete).eval()
    frames = torch.from_numpy(obs.astype(np.float32))  # (T, H, W, 3) in [0, 255]
    if policy.discrete:
        target = torch.as_tensor(np.asarray(demo_actions, np.int64))  # (T,)
        extra: dict = {"target": target}
    else:
        a = torch.as_tensor(np.asarray(demo_actions, np.float32).reshape(len(obs), -1))
        extra = {"additional_forward_args": (a,)}  # (T, A)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        if method == "integrated_gradients":
            raw = _integrated_gradients(model, frames, extra, config)
        elif method == "occlusion":
            raw = _occlusion(model, frames, extra, config)
        elif method == "grad_cam":
            raw = _grad_cam(model, net, frames, extra)
        else:
            if features is None or features.shape != obs.shape[:3]:
                raise UserError("kernel_shap needs object labels (T, H, W) for the frames")
            raw = _kernel_shap(model, frames, extra, features, config)
    raw = raw.detach()  # (T, H, W, 3) per channel, or (T, H, W)
    if raw.ndim == 4:
        unsigned, signed = raw.abs().sum(dim=-1), raw.sum(dim=-1)
    else:
        unsigned, signed = raw.abs(), raw
    out = unsigned.numpy().astype(np.float32), signed.numpy().astype(np.float32)
    if not (np.isfinite(out[0]).all() and np.isfinite(out[1]).all()):
        raise UserError(
            f"{method} gave non-finite attributions (NaN or inf) for this policy: no saliency "
            "map or ranking is computed from them"
        )
    return np.maximum(out[0], 0.0), out[1]


# -- the explained number ----------------------------------------------------------------------
class _Explained(nn.Module):
    """float32 frames (B, H, W, 3) in [0, 255] -> the number explained: logits (B, n) whose
    demonstrated entry captum picks (discrete), or -||pi(s) - a||_2 (B,) for the demonstrated
    actions a (B, A) (continuous; +1e-12 under the root keeps its gradient finite at 0)."""

    def __init__(self, net: Explainable, discrete: bool) -> None:
        super().__init__()
        self.net = net
        self.discrete = discrete

    def forward(self, frames: torch.Tensor, demo: torch.Tensor | None = None) -> torch.Tensor:
        out = self.net.pixels(frames)  # (B, A | n)
        if self.discrete:
            return out
        assert demo is not None, "continuous actions are explained against demonstrated ones"
        return -torch.sqrt(((out - demo) ** 2).sum(dim=1) + 1e-12)  # (B,)


def check_explainable(policy: Policy) -> None:
    """Refuse (UserError) a policy whose network the methods cannot take apart."""
    _image_net(policy)


def _image_net(policy: Policy) -> Explainable:
    if not isinstance(policy.net, Explainable):
        raise UserError(
            "saliency maps need an image policy whose network they can take apart (a checkpoint "
            "folder, a base policy or a stable-baselines3 CnnPolicy); this policy's network is "
            f"{type(policy.net).__name__ if policy.net is not None else 'not available'}"
        )
    return policy.net


# -- the methods ---------------------------------------------------------------------------------
def _integrated_gradients(model, frames, extra, config: SaliencyConfig) -> torch.Tensor:
    from captum.attr import IntegratedGradients

    attr = IntegratedGradients(model).attribute(
        frames,
        baselines=0.0,
        n_steps=config.ig_steps,
        internal_batch_size=config.batch,
        **extra,
    )  # (T, H, W, 3)
    return attr


def occlusion_window(h: int, config: SaliencyConfig = SaliencyConfig()) -> tuple[int, int]:
    """(patch side, stride) in pixels for frames of height h."""
    k = config.occlusion_px or max(3, h // 12)
    return k, max(1, k // 2)


def _occlusion(model, frames, extra, config: SaliencyConfig) -> torch.Tensor:
    from captum.attr import Occlusion

    k, stride = occlusion_window(frames.shape[1], config)
    per_eval = max(1, config.batch // len(frames))
    with torch.no_grad():
        attr = Occlusion(model).attribute(
            frames,
            sliding_window_shapes=(k, k, 3),
            strides=(stride, stride, 3),
            baselines=0.0,
            perturbations_per_eval=per_eval,
            **extra,
        )  # (T, H, W, 3)
    return attr


def grad_cam_layer(net: Explainable) -> nn.Conv2d:
    """The network's last convolution whose output has more than one cell on its frames (the
    last one when every output is a single cell)."""
    convs = net.convolutions()
    sizes: list[tuple[int, int]] = []
    hooks = [c.register_forward_hook(lambda _m, _i, o: sizes.append(o.shape[-2:])) for c in convs]
    try:
        with torch.no_grad():
            net.pixels(torch.zeros(1, *net.frame_shape))
    finally:
        for hook in hooks:
            hook.remove()
    spatial = [c for c, (a, b) in zip(convs, sizes, strict=True) if a * b > 1]
    return (spatial or convs)[-1]


def _grad_cam(model, net: Explainable, frames, extra) -> torch.Tensor:
    from captum.attr import LayerAttribution, LayerGradCam

    cam = LayerGradCam(model, grad_cam_layer(net)).attribute(
        frames, relu_attributions=False, **extra
    )  # (T, 1, h, w)
    up = LayerAttribution.interpolate(cam, tuple(frames.shape[1:3]), interpolate_mode="bilinear")
    return up[:, 0]  # (T, H, W), signed


def _kernel_shap(model, frames, extra, features: np.ndarray, config) -> torch.Tensor:
    from captum._utils.models.linear_model import LinearModel
    from captum.attr import KernelShap

    shap = KernelShap(model)
    shap.interpretable_model = LinearModel(train_fn=_weighted_least_squares)
    out = torch.zeros(frames.shape[:3])  # (T, H, W)
    for t in range(len(frames)):
        ids, inverse = np.unique(features[t], return_inverse=True)
        labels = torch.from_numpy(inverse.reshape(features[t].shape))  # (H, W) in 0 .. F-1
        one = {k: _row(v, t) for k, v in extra.items()}
        x = frames[t : t + 1]  # (1, H, W, 3)
        if len(ids) == 1:  # one feature: its Shapley value is the whole change
            with torch.no_grad():
                phi = _scalar(model, x, one) - _scalar(model, torch.zeros_like(x), one)
            values = phi.reshape(1)
        else:
            mask = labels[None, :, :, None].expand(1, *labels.shape, 3)  # (1, H, W, 3)
            with torch.no_grad():
                values = shap.attribute(
                    x,
                    baselines=0.0,
                    feature_mask=mask,
                    n_samples=config.shap_samples,
                    perturbations_per_eval=config.shap_samples,
                    return_input_shape=False,
                    **one,
                ).reshape(-1)  # (F,)
        counts = torch.bincount(labels.reshape(-1), minlength=len(ids)).clamp(min=1)
        out[t] = (values / counts)[labels]  # signed
    return out


def _row(value, t: int):
    """One frame's part of a target or of the extra forward arguments."""
    if isinstance(value, tuple):
        return tuple(v[t : t + 1] for v in value)
    return value[t : t + 1]


def _scalar(model, x, one: dict) -> torch.Tensor:
    args = one.get("additional_forward_args", ())
    out = model(x, *args)
    if "target" in one:
        out = out.gather(1, one["target"].reshape(-1, 1))
    return out.reshape(-1)


def _weighted_least_squares(model, dataloader, construct_kwargs, **_) -> dict:
    """captum's interpretable-model training hook, solved exactly: the linear model of the
    coalitions (B, F) that fits the outputs (B,) under the Shapley kernel's weights (B,)."""
    xs, ys, ws = zip(*dataloader, strict=True)
    x = torch.cat(xs).double()  # (B, F)
    y = torch.cat(ys).double().reshape(-1)  # (B,)
    w = torch.cat(ws).double().reshape(-1).sqrt()  # (B,)
    design = torch.cat([x, torch.ones(len(x), 1, dtype=x.dtype)], dim=1) * w[:, None]
    coef = torch.linalg.lstsq(design, y * w, driver="gelsd").solution  # (F + 1,)
    model._construct_model_params(
        norm_type=None,
        weight_values=coef[:-1].float().reshape(1, -1),
        bias_value=coef[-1:].float(),
    )
    return {}
