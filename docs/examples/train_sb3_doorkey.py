"""Train the PPO agent of the "Bring your own policy" walkthrough, and export it to ONNX.

    .venv/bin/python docs/examples/train_sb3_doorkey.py [--steps 300000] [--out docs/examples]

stable-baselines3's PPO with its CnnPolicy on MiniGrid-DoorKey-5x5-v0 seen through
RGBImgObsWrapper(tile_size=12) + ImgObsWrapper (60x60 RGB frames of the whole grid): 8 envs,
n_steps 128, batch 256, 4 epochs, learning rate 5e-4, entropy coefficient 0.01, seed 0. About
four minutes on 2 CPU cores. Writes:

    doorkey5x5_ppo.zip    the trained model (stable-baselines3's format, without the
                          optimizer's state, which diagnosis and finetuning do not use)
    doorkey5x5_ppo.onnx   its policy network as an ONNX graph: uint8 frames (B, 60, 60, 3) in,
                          the 7 actions' logits out
    doorkey5x5_ppo.json   how it was trained, and its success on 30 fresh layouts

    dfa run --world minigrid:MiniGrid-DoorKey-5x5-v0:tile=12 \\
            --policy sb3:docs/examples/doorkey5x5_ppo.zip

then diagnoses it (the committed copies are the ones the tests use).
"""

from __future__ import annotations

import io
import json
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import minigrid  # noqa: F401 (registers the MiniGrid ids)
import numpy as np
import torch
import tyro
from minigrid.wrappers import ImgObsWrapper, RGBImgObsWrapper
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env

ENV_ID, TILE = "MiniGrid-DoorKey-5x5-v0", 12
WORLD = f"minigrid:{ENV_ID}:tile={TILE}"
SETTINGS = dict(n_steps=128, batch_size=256, n_epochs=4, learning_rate=5e-4, ent_coef=0.01)


def wrapped(**kwargs):
    return ImgObsWrapper(RGBImgObsWrapper(gym.make(ENV_ID, **kwargs), tile_size=TILE))


def solved(model: PPO, episodes: int = 30, first_seed: int = 10_000) -> int:
    env, wins = wrapped(), 0
    for k in range(episodes):
        obs, _ = env.reset(seed=first_seed + k)
        for _ in range(env.unwrapped.max_steps):
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action))
            if terminated or truncated:
                wins += reward > 0
                break
    return wins


def strip_optimizer(path: Path) -> None:
    """Rewrite the zip without policy.optimizer.pth (the Adam state: 2/3 of its size)."""
    with zipfile.ZipFile(path) as z:
        kept = {n: z.read(n) for n in z.namelist() if n != "policy.optimizer.pth"}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in kept.items():
            z.writestr(name, data)


@dataclass(frozen=True)
class Args:
    """Train the PPO agent of the "Bring your own policy" walkthrough, and export it to ONNX."""

    steps: int = 300_000
    """Environment steps PPO trains for."""
    out: Path = Path(__file__).parent
    """Folder for the .zip, the .onnx and the .json."""


def main() -> None:
    args = tyro.cli(Args)
    torch.manual_seed(0)
    envs = make_vec_env(wrapped, n_envs=8, seed=0)
    model = PPO("CnnPolicy", envs, seed=0, verbose=0, **SETTINGS)
    t0 = time.perf_counter()
    model.learn(args.steps)
    seconds = time.perf_counter() - t0
    zip_path = args.out / "doorkey5x5_ppo.zip"
    model.save(zip_path)
    strip_optimizer(zip_path)
    wins = solved(model)

    # the policy network as ONNX: the project's loader makes the module that takes uint8 frames
    from policy.outside import load
    from sim import get_world

    world = get_world(WORLD)
    net = load(f"sb3:{zip_path}", world).net
    frames = torch.from_numpy(world.render_batch([world.sample_scene(0), world.sample_scene(1)]))
    buf = io.BytesIO()
    torch.onnx.export(
        net,
        (frames,),
        buf,
        input_names=["frame"],
        output_names=["logits"],
        dynamic_axes={"frame": {0: "batch"}, "logits": {0: "batch"}},
        dynamo=False,
    )
    (args.out / "doorkey5x5_ppo.onnx").write_bytes(buf.getvalue())
    info = {
        "env": ENV_ID,
        "wrappers": f"RGBImgObsWrapper(tile_size={TILE}) + ImgObsWrapper",
        "world": WORLD,
        "algorithm": "PPO CnnPolicy",
        "settings": {**SETTINGS, "n_envs": 8, "total_timesteps": args.steps, "seed": 0},
        "train_seconds": round(seconds, 1),
        "solved_of_30_fresh_layouts": int(wins),
        "torch": torch.__version__,
        "numpy": np.__version__,
    }
    (args.out / "doorkey5x5_ppo.json").write_text(json.dumps(info, indent=2) + "\n")
    print(json.dumps(info, indent=2))


if __name__ == "__main__":
    main()
