"""What a policy from outside expects of the world's frames, and the pieces every loader shares.

    ObsSpec.parse("chw,scale=1/255")   the declared conversion of the world's uint8 (B, H, W, 3)
                                       frames: `chw` (channels first), `float` (float32),
                                       `scale=X` (multiplied by X), `frames=N` (only 1)
    Converted(module, obs)             a module that takes converted frames, as one that takes
                                       the world's uint8 frames (what finetuning trains)
    split_obs("PATH#chw")              ("PATH", its ObsSpec, "#chw"): a spec's target and its
                                       declared conversion
    said(e)                            an exception as a few words on one line

Nothing is guessed: a policy whose input does not take the converted frames is a one-line
error naming both shapes (policy.loaders checks every loaded policy on one frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import torch
from torch import nn

from sim.core import UserError

MAX_WEIGHTS_BYTES = 1 << 30  # a weights file (or an sb3 zip's policy.pth) read whole


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


def said(e: BaseException) -> str:
    """An exception as a few words on one line."""
    text = str(e).strip().splitlines()[0][:160] if str(e).strip() else ""
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def split_obs(target: str) -> tuple[str, ObsSpec, str]:
    """ "WHAT#OBS" -> (WHAT, the parsed ObsSpec, "#OBS" as given, or "" when none was)."""
    what, _, text = target.partition("#")
    return what, ObsSpec.parse(text), f"#{text}" if text else ""
