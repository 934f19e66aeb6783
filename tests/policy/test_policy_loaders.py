"""Policy loaders registered from outside the checkout: docs/bring-your-own.md's `npz:` loader,
registered by "module:function", loads, finetunes and comes back from its checkpoint; a prefix
is never taken over; whatever an outside loader gets wrong is one line; an unknown prefix names
the accepted ones; and an installed package's "dfa.policies" entry point and DFA_POLICIES reach
`dfa run`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from policy import register_policy_loader
from policy.checkpoint import save_policy
from policy.loaders import loader_prefixes
from policy.model import Origin, Policy
from policy.outside import load
from policy.train import TrainConfig, finetune, training_demos
from sim import get_world
from sim.core import UserError, files

REPO = Path(__file__).resolve().parents[2]
DFA = Path(sys.executable).parent / "dfa"


def docs_loader() -> str:
    """The npz loader of docs/bring-your-own.md, as written there."""
    page = (REPO / "docs" / "bring-your-own.md").read_text()
    return page.split("### Your own policy format")[1].split("```python")[1].split("```")[0]


@pytest.fixture
def npz_module(tmp_path, monkeypatch):
    (tmp_path / "docs_npz.py").write_text(docs_loader())
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


@pytest.fixture(scope="module")
def nav():
    return get_world("nav2d")  # (36, 36, 3) frames, 2-d continuous actions


def linear_npz(path: Path, world, *, seed: int = 0, inputs: int | None = None) -> Path:
    gen = np.random.default_rng(seed)
    n = inputs or int(np.prod(world.obs_shape))
    w = gen.normal(0, 1e-3, (world.action_dim, n)).astype(np.float32)
    np.savez(path, W=w, b=np.array([0.3, -0.2], np.float32))
    return path


def test_a_loader_registered_by_module_function_is_used(npz_module, nav, tmp_path):
    register_policy_loader("npz", "docs_npz:load")
    register_policy_loader("npz", "docs_npz:load")  # the same again: nothing changes
    assert "npz" in loader_prefixes()
    path = linear_npz(tmp_path / "linear.npz", nav)
    policy = load(f"npz:{path}", nav)
    frames = nav.render_batch([nav.train_task(s).scene for s in range(4)])
    with np.load(path) as f:  # what the stored arrays give, computed here
        want = frames.reshape(4, -1).astype(np.float32) / 255 @ f["W"].T + f["b"]
    np.testing.assert_allclose(policy.outputs(frames), want, rtol=1e-4, atol=1e-5)
    assert policy.source == f"npz:{path.resolve()}"
    assert policy.origin == Origin("npz", "linear.npz", files.sha256(path))
    tuned, _ = finetune(nav, policy, training_demos(nav)[:2], config=TrainConfig(steps=3))
    folder = save_policy(tuned, tmp_path / "tuned")
    assert json.loads((folder / "config.json").read_text())["origin"]["kind"] == "npz"
    back = load(f"npz:{path}", nav, weights=folder)
    np.testing.assert_array_equal(back.outputs(frames), tuned.outputs(frames))
    with pytest.raises(UserError, match=r"W has shape \(2, 7\), which does not fit nav2d"):
        load(f"npz:{linear_npz(tmp_path / 'small.npz', nav, inputs=7)}", nav)


def test_a_prefix_is_never_taken_over(npz_module):
    with pytest.raises(UserError, match="a policy loader for onnx: is already registered") as err:
        register_policy_loader("onnx", "docs_npz:load")
    assert "(policy.onnx_policy:load)" in str(err.value) and "\n" not in str(err.value)
    register_policy_loader("npz-taken", "docs_npz:load")
    with pytest.raises(UserError, match="already registered"):
        register_policy_loader("npz-taken", lambda target, world: None)
    for prefix in ("", "a:b", "1st", "./here", "x y"):
        with pytest.raises(UserError, match="a policy loader's prefix is a letter"):
            register_policy_loader(prefix, "docs_npz:load")
    with pytest.raises(UserError, match="is not module:function"):
        register_policy_loader("spaced", "docs_npz load")


def _raises(target, world):
    raise ValueError("no policy today")


def _exits(target, world):
    raise SystemExit(3)


def _not_a_policy(target, world):
    return np.zeros((1, world.action_dim))


def _no_origin(target, world):
    from policy.base import base_policy

    return Policy(base_policy(world).net)


class FirstThree(torch.nn.Module):
    def forward(self, obs: torch.Tensor) -> torch.Tensor:  # uint8 (B, H, W, 3) -> (B, 3)
        return obs.float().flatten(1)[:, :3]


def _three_actions(target, world):
    origin = Origin("three", "f", "0" * 64)
    return Policy(
        FirstThree(), discrete=False, obs_shape=world.obs_shape, action_dim=2, origin=origin
    )


@pytest.mark.parametrize(
    ("loader", "spec", "message"),
    [
        (_raises, "raises:a", r"^raises:a: its loader raised ValueError: no policy today$"),
        (_exits, "exits:a", r"^exits:a: its loader raised SystemExit: 3$"),
        (_not_a_policy, "array:a", "its loader gave a ndarray, not a policy.model.Policy"),
        (_no_origin, "bare:a", "its loader recorded no origin"),
        (_three_actions, "three:a", r"outputs of shape \(3,\) per frame, but nav2d needs 2"),
        ("nosuch_module:load", "gone:a", "its loader nosuch_module:load: no module"),
        ("docs_npz:nothing", "absent:a", "module docs_npz has no nothing"),
        (None, "nowhere:a", r"no policy loader for nowhere:; accepted: DIR .*, sb3:\.\.\."),
    ],
)
def test_what_an_outside_loader_gets_wrong_is_one_line(npz_module, nav, loader, spec, message):
    if loader is not None:
        register_policy_loader(spec.split(":")[0], loader)
    with pytest.raises(UserError, match=message) as err:
        load(spec, nav)
    assert "\n" not in str(err.value)


def test_a_folder_whose_name_looks_like_a_spec_is_a_checkpoint(nav, tmp_path, monkeypatch):
    from policy.base import base_policy

    policy = base_policy(nav)
    save_policy(policy, tmp_path / "run:1")
    monkeypatch.chdir(tmp_path)
    frames = nav.render_batch([nav.sample_scene(0)])
    np.testing.assert_array_equal(load("run:1", nav).outputs(frames), policy.outputs(frames))
    with pytest.raises(UserError, match=r"^run:2: no policy loader for run:; accepted: DIR"):
        load("run:2", nav)


def _dfa(args: list[str], cwd: Path, **env: str) -> subprocess.CompletedProcess:
    full = {**os.environ, "PYTHONPATH": str(cwd), **env}
    return subprocess.run(
        [str(DFA), *args], cwd=cwd, env=full, capture_output=True, text=True, timeout=900
    )


def _package(folder: Path, entry_points: str) -> None:
    """A package's metadata on the path, as pip install leaves it."""
    (folder / "docs_npz.py").write_text(docs_loader())
    info = folder / "lab_policies-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: lab-policies\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[dfa.policies]\n{entry_points}\n")


def test_an_entry_point_and_dfa_policies_reach_dfa_run(tmp_path, nav):
    """`dfa run --policy npz:...` diagnoses the policy an installed package's loader gives (its
    recording is named after the file that loader read); DFA_POLICIES names another prefix;
    an entry point that would take over a prefix is one line and exit 2."""
    _package(tmp_path, "npz = docs_npz:load")
    linear_npz(tmp_path / "linear.npz", nav)
    ran = _dfa(["run", "--world", "nav2d", "--policy", "npz:linear.npz", "--json"], tmp_path)
    assert ran.returncode == 0, ran.stderr[-2000:]
    report = json.loads(ran.stdout)
    digest = files.sha256(tmp_path / "linear.npz")[:8]
    assert Path(report["recording"]).name == f"nav2d-object_ti-seed0-linear-{digest}.rrd"
    assert report["success_before"] is not None

    linear_npz(tmp_path / "wide.npz", nav, inputs=5)
    args = ["run", "--world", "nav2d", "--policy", "listed:wide.npz"]
    listed = _dfa(args, tmp_path, DFA_POLICIES="listed=docs_npz:load")
    assert listed.returncode == 2 and listed.stderr.count("\n") == 1, listed.stderr[-2000:]
    assert "wide.npz: W has shape (2, 5), which does not fit nav2d" in listed.stderr
    unknown = _dfa(args, tmp_path)  # without DFA_POLICIES, listed: is no prefix
    assert unknown.returncode == 2 and "no policy loader for listed:" in unknown.stderr

    taken = tmp_path / "taken"
    taken.mkdir()
    _package(taken, "onnx = docs_npz:load")
    refused = _dfa(["run", "--world", "nav2d", "--policy", "onnx:x.onnx"], taken)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr[-2000:]
    assert "entry point onnx = docs_npz:load of lab-policies names a prefix" in refused.stderr
