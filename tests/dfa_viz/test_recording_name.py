"""Runs of different policies on the same world, shift and seed write different recordings:
the file name carries the policy (its file's name and sha256); the base policy's keeps the
plain <world>-<shift>-seed<seed>.rrd."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

from dfa_viz.assemble import recording_name
from dfa_viz.cli import main
from policy.base import WEIGHTS
from policy.outside import load
from sim import get_world
from sim.core import files

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
ZIP = EXAMPLES / "doorkey5x5_ppo.zip"


def test_names_carry_the_policy_file_and_its_sha256(nav, nav_policy, tmp_path):
    assert recording_name(nav, "object_ti", 3, nav_policy, None, None) == (
        "nav2d-object_ti-seed3.rrd"
    )
    folder = WEIGHTS / "nav2d"
    digest = files.sha256(folder / "model.safetensors")
    assert recording_name(nav, "object_ti", 3, nav_policy, str(folder), None) == (
        f"nav2d-object_ti-seed3-nav2d-{digest[:8]}.rrd"
    )
    world = get_world("minigrid:MiniGrid-DoorKey-5x5-v0:tile=12")
    ppo = load(f"sb3:{ZIP}", world)
    plain = recording_name(world, "object_ti", 2, ppo, f"sb3:{ZIP}", None)
    sha = files.sha256(ZIP)
    assert (
        plain
        == f"minigrid_MiniGrid-DoorKey-5x5-v0_tile_12-object_ti-seed2-doorkey5x5_ppo-{sha[:8]}.rrd"
    )
    tuned = tmp_path / "policy-0001"
    tuned.mkdir()
    shutil.copy(folder / "model.safetensors", tuned / "model.safetensors")
    both = hashlib.sha256(f"{sha}{digest}".encode()).hexdigest()
    with_weights = recording_name(world, "object_ti", 2, ppo, f"sb3:{ZIP}", tuned)
    assert with_weights == plain.replace(sha[:8], both[:8]) != plain


def test_two_policies_on_one_task_keep_two_recordings(tmp_path, capsys):
    """The base policy and the same weights given as a checkpoint folder, on one task: two
    files, each the one its report names."""
    args = ["run", "--shift", "object_ti", "--seed", "0", "--json", "--out", str(tmp_path)]
    quick = ["--budget", "2", "--steps", "5", "--n-eval", "2"]
    assert main([*args, *quick]) == 0
    base = json.loads(capsys.readouterr().out)["recording"]
    assert main([*args, *quick, "--policy", str(WEIGHTS / "nav2d")]) == 0
    other = json.loads(capsys.readouterr().out)["recording"]
    assert Path(base).name == "nav2d-object_ti-seed0.rrd"
    assert Path(other).name.startswith("nav2d-object_ti-seed0-nav2d-") and other != base
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([Path(base).name, Path(other).name])
