"""Policies from outside cannot spend memory before they are refused, and every way one can be
wrong is one line: each case runs `dfa run` in a child process under an address-space limit
(resource.setrlimit) and asserts exit 2, one line on stderr, and a bounded peak."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest

from policy.sb3_policy import MAX_DATA_BYTES

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
ZIP, ONNX = EXAMPLES / "doorkey5x5_ppo.zip", EXAMPLES / "doorkey5x5_ppo.onnx"
WORLD = "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12"
LIMIT_BYTES = 3 << 30  # the child's address space: torch and onnxruntime need about 0.7 GiB
PEAK_BYTES = 1536 << 20  # what a refused policy may cost at most (resident)

CHILD = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({limit}, {limit}))
from dfa_viz.cli import main
code = main(sys.argv[1:])
peak_kb = int(open("/proc/self/status").read().split("VmHWM:")[1].split()[0])
print("peak", peak_kb * 1024)
sys.exit(code)
"""


def refused(*args: str, cwd: Path) -> str:
    """Run `dfa run --world WORLD ARGS` in a child under LIMIT_BYTES; its one error line."""
    out = subprocess.run(
        [sys.executable, "-c", CHILD.format(limit=LIMIT_BYTES), "run", "--world", WORLD, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2, (out.returncode, out.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith("dfa: error: "), out.stderr[-2000:]
    peak = int(out.stdout.split("peak")[1])
    assert peak < PEAK_BYTES, f"peak {peak >> 20} MiB"
    assert not (cwd / "recordings").exists()  # nothing written
    return lines[0]


def _members() -> dict[str, bytes]:
    with zipfile.ZipFile(ZIP) as z:
        return {n: z.read(n) for n in z.namelist()}


def _zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, blob in members.items():
            z.writestr(name, blob)
    return path


def _bomb_zip(path: Path, inflated_bytes: int) -> Path:
    """The example zip with a `data` member of JSON whitespace that really inflates to
    `inflated_bytes`, written by hand (a stream of identical deflate blocks) in a second."""
    block = b" " * (16 << 20)
    assert inflated_bytes % len(block) == 0
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    one = c.compress(block) + c.flush(zlib.Z_FULL_FLUSH)  # the same bytes for every block
    end = c.flush(zlib.Z_FINISH)
    n = inflated_bytes // len(block)
    crc = 0
    for _ in range(n):
        crc = zlib.crc32(block, crc)
    entries = [("data", 8, crc, one * n + end, inflated_bytes)]
    for name, blob in _members().items():
        if name != "data":
            entries.append((name, 0, zlib.crc32(blob), blob, len(blob)))
    central, offset = b"", 0
    with open(path, "wb") as f:
        for name, method, crc, raw, size in entries:
            key = name.encode()
            head = struct.pack(
                "<4s5H3L2H", b"PK\x03\x04", 20, 0, method, 0, 0, crc, len(raw), size, len(key), 0
            )
            f.write(head + key + raw)
            central += (
                struct.pack(
                    "<4s6H3L5H2L",
                    b"PK\x01\x02",
                    20,
                    20,
                    0,
                    method,
                    0,
                    0,
                    crc,
                    len(raw),
                    size,
                    len(key),
                    0,
                    0,
                    0,
                    0,
                    0,
                    offset,
                )
                + key
            )
            offset += len(head) + len(key) + len(raw)
        f.write(central)
        f.write(
            struct.pack(
                "<4s4H2LH", b"PK\x05\x06", 0, 0, len(entries), len(entries), len(central), offset, 0
            )
        )
    return path


def test_an_sb3_data_member_that_inflates_past_the_limit_is_not_read(tmp_path):
    bomb = _bomb_zip(tmp_path / "bomb.zip", 144 * (16 << 20))  # 2.25 GiB of whitespace
    with zipfile.ZipFile(bomb) as z:
        assert z.getinfo("data").file_size > MAX_DATA_BYTES
    line = refused("--policy", f"sb3:{bomb}", cwd=tmp_path)
    assert "its data inflates to 2304 MiB, over the 64 MiB accepted" in line


def test_a_huge_net_arch_is_compared_with_the_stored_shapes_before_it_is_built(tmp_path):
    members = _members()
    data = json.loads(members["data"])
    data["policy_kwargs"] = {"net_arch": [1_500_000]}
    members["data"] = json.dumps(data).encode()
    line = refused("--policy", f"sb3:{_zip(tmp_path / 'wide.zip', members)}", cwd=tmp_path)
    assert "policy.pth does not fit the ActorCriticCnnPolicy its settings describe" in line


def _onnx(path: Path, out_shape: list, n: int) -> Path:
    """A graph that takes the world's frames and gives a constant of shape (1, n), declaring
    `out_shape` as its output."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    x = helper.make_tensor_value_info("frame", TensorProto.UINT8, ["batch", 60, 60, 3])
    shape = numpy_helper.from_array(np.array([1, n], np.int64), "shape")
    one = numpy_helper.from_array(np.array([1.0], np.float32), "one")
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, out_shape)
    graph = helper.make_graph(
        [helper.make_node("Expand", ["one", "shape"], ["logits"])], "g", [x], [y], [shape, one]
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


@pytest.mark.parametrize("declared", [["batch", "n"], ["batch", 7]])
def test_an_onnx_output_of_two_billion_values_is_refused_before_it_is_run(tmp_path, declared):
    graph = _onnx(tmp_path / "huge.onnx", declared, 2_000_000_000)
    line = refused("--policy", f"onnx:{graph}", cwd=tmp_path)
    assert "the graph's output 'logits' has shape [1, " in line
    assert "a policy gives (batch, 7)" in line


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: [1, 2], "its data is JSON list, not an object"),
        (lambda d: d | {"observation_space": [3, 60, 60]}, "its observation_space is JSON list"),
        (lambda d: d | {"action_space": "Discrete(7)"}, "its action_space is JSON str"),
        (lambda d: "[" * 200_000 + "]" * 200_000, "not a stable-baselines3 .zip"),
    ],
)
def test_sb3_data_of_the_wrong_shape_is_one_line(tmp_path, change, message):
    members = _members()
    data = change(json.loads(members["data"]))
    members["data"] = (data if isinstance(data, str) else json.dumps(data)).encode()
    line = refused("--policy", f"sb3:{_zip(tmp_path / 'odd.zip', members)}", cwd=tmp_path)
    assert message in line


USER_CODE = """
import sys
from torch import nn
def raises():
    raise ValueError("no network today")
def exits():
    raise SystemExit(0)
def module():
    return nn.Linear(2, 2)
"""


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("torch:user_code:raises@{w}", "raises() raised ValueError: no network today"),
        ("torch:user_code:exits@{w}", "exits() raised SystemExit"),
        ("torch:user_code:module@{w}#scale=1e400", "observation option 'scale=1e400'"),
        ("torch:user_code:module@{w}#scale=0", "observation option 'scale=0'"),
        ("torch:user_code:module@missing.safetensors", "missing.safetensors: no such file"),
    ],
)
def test_a_torch_callable_that_fails_is_one_line_and_never_exit_0(tmp_path, spec, message):
    (tmp_path / "user_code.py").write_text(USER_CODE)
    from safetensors.torch import save_file
    from torch import nn

    save_file(nn.Linear(2, 2).state_dict(), str(tmp_path / "w.safetensors"))
    line = refused("--policy", spec.format(w=tmp_path / "w.safetensors"), cwd=tmp_path)
    assert message in line
