"""Train the PPO agent of the "Bring your own policy" walkthrough, and export it to ONNX.

    .venv/bin/python docs/examples/train_sb3_doorkey.py [--env MiniGrid-DoorKey-5x5-v0]
        [--tile 12] [--steps 300000] [--out .]

stable-baselines3's PPO with its CnnPolicy on a MiniGrid environment (MiniGrid-DoorKey-5x5-v0
by default) seen through RGBImgObsWrapper(tile_size=12) + ImgObsWrapper (60x60 RGB frames of
the whole 5x5 grid): 8 envs, n_steps 128, batch 256, 4 epochs, learning rate 5e-4, entropy
coefficient 0.01, seed 0. About four minutes on 2 CPU cores. Writes, in the current folder
(or --out), files named after the environment (doorkey5x5 for MiniGrid-DoorKey-5x5-v0):

    doorkey5x5_ppo.zip    the trained model in stable-baselines3's format; PPO.load opens it.
                          Its optimizer keeps Adam's settings but not its running averages
                          (2/3 of the file, which neither diagnosis nor finetuning uses): a
                          model loaded to train on starts them afresh
    doorkey5x5_ppo.onnx   its policy network as an ONNX graph: uint8 frames (B, 60, 60, 3) in,
                          the 7 actions' logits out
    doorkey5x5_ppo.json   how it was trained, its success on 30 fresh layouts (--episodes),
                          the zip's sha256

    dfa run --world minigrid:MiniGrid-DoorKey-5x5-v0:tile=12 --policy sb3:doorkey5x5_ppo.zip

then diagnoses it (the committed copies in docs/examples are the ones the tests use).

A zip an earlier version of this script wrote has no optimizer at all, and PPO.load refuses it
(KeyError: 'policy.optimizer'); `--repair FILE.zip` adds the optimizer's settings, leaves every
other byte of it as it is (the weights too), and updates the sha256 in the .json beside it.
"""

from __future__ import annotations

import io
import json
import re
import time
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

SETTINGS = dict(n_steps=128, batch_size=256, n_epochs=4, learning_rate=5e-4, ent_coef=0.01)


@dataclass(frozen=True)
class Args:
    """Train the PPO agent of the "Bring your own policy" walkthrough, and export it to ONNX."""

    env: str = "MiniGrid-DoorKey-5x5-v0"
    """A MiniGrid environment id."""
    tile: int = 12
    """Pixels per grid cell of the frames the agent sees (RGBImgObsWrapper's tile_size)."""
    steps: int = 300_000
    """Environment steps PPO trains for."""
    episodes: int = 30
    """Fresh layouts (reset seeds 10,000 on) the trained agent is scored on."""
    out: Path = Path(".")
    """Folder for the .zip, the .onnx and the .json."""
    repair: Path | None = None
    """Instead of training: add the optimizer that a zip written by an earlier version of this
    script lacks, so that PPO.load opens it (--env and --tile say what it was trained on)."""


def stem(env_id: str) -> str:
    """The files' name for an environment: MiniGrid-DoorKey-5x5-v0 -> doorkey5x5."""
    core = re.sub(r"-v\d+$", "", env_id.removeprefix("MiniGrid-").removeprefix("BabyAI-"))
    return re.sub(r"[^a-z0-9]", "", core.lower())


def wrapped(env_id: str, tile: int, **kwargs):
    return ImgObsWrapper(RGBImgObsWrapper(gym.make(env_id, **kwargs), tile_size=tile))


def solved(model: PPO, env, episodes: int, first_seed: int = 10_000) -> int:
    wins = 0
    for k in range(episodes):
        obs, _ = env.reset(seed=first_seed + k)
        for _ in range(env.unwrapped.max_steps):
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action))
            if terminated or truncated:
                wins += reward > 0
                break
    return wins


def without_averages(model: PPO, path: Path) -> None:
    """Rewrite the zip with its optimizer's settings but not Adam's running averages."""
    from policy.sb3zip import OPTIMIZER, fresh_optimizer, members, tensor_bytes, write_zip

    contents = members(path)
    contents[OPTIMIZER] = tensor_bytes(fresh_optimizer(model.policy, contents["data"]))
    write_zip(path, contents, like=path)


def repair(path: Path, world_name: str) -> None:
    """Add the optimizer a zip lacks (policy.sb3zip.with_optimizer), then the zip's new sha256
    to the .json beside it."""
    from policy.outside import load
    from policy.sb3zip import with_optimizer
    from sim import get_world
    from sim.core import files

    sb3_policy = load(f"sb3:{path}", get_world(world_name)).net.policy
    added = with_optimizer(path, sb3_policy)
    info_path = path.with_suffix(".json")
    if info_path.is_file():
        info = json.loads(info_path.read_text())
        info["zip_sha256"] = files.sha256(path)
        files.write_text(info_path, json.dumps(info, indent=2) + "\n")
    print(f"{path}: {'optimizer added' if added else 'already has an optimizer'}")


def main() -> None:
    args = tyro.cli(Args)
    from sim import get_world
    from sim.core import files

    world_name = f"minigrid:{args.env}:tile={args.tile}"
    world = get_world(world_name)  # an unknown environment or tile: one line, before training
    if args.repair is not None:
        repair(args.repair, world_name)
        return
    torch.manual_seed(0)
    envs = make_vec_env(lambda **kw: wrapped(args.env, args.tile, **kw), n_envs=8, seed=0)
    model = PPO("CnnPolicy", envs, seed=0, verbose=0, **SETTINGS)
    t0 = time.perf_counter()
    model.learn(args.steps)
    seconds = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    name = stem(args.env)
    zip_path = args.out / f"{name}_ppo.zip"
    model.save(zip_path)
    without_averages(model, zip_path)
    wins = solved(model, wrapped(args.env, args.tile), args.episodes)

    # the policy network as ONNX: the project's loader makes the module that takes uint8 frames
    from policy.outside import load

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
    files.write_bytes(args.out / f"{name}_ppo.onnx", buf.getvalue())
    info = {
        "env": args.env,
        "wrappers": f"RGBImgObsWrapper(tile_size={args.tile}) + ImgObsWrapper",
        "world": world_name,
        "algorithm": "PPO CnnPolicy",
        "settings": {**SETTINGS, "n_envs": 8, "total_timesteps": args.steps, "seed": 0},
        "train_seconds": round(seconds, 1),
        f"solved_of_{args.episodes}_fresh_layouts": int(wins),
        "optimizer": "Adam's settings without its running averages",
        "zip_sha256": files.sha256(zip_path),
        "torch": torch.__version__,
        "numpy": np.__version__,
    }
    files.write_text(args.out / f"{name}_ppo.json", json.dumps(info, indent=2) + "\n")
    print(json.dumps(info, indent=2))


if __name__ == "__main__":
    main()
