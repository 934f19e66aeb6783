"""The saliency of a failed rollout as a layer over its frames: `dfa run --saliency` records
it, read back from the .rrd; the heat colouring; bad methods and policies refused."""

import numpy as np
import pytest
import rerun as rr

from dfa_viz.cli import main
from dfa_viz.overlay import ALPHA_MAX, blend, heat_rgba
from policy import failing_test_task
from policy.saliency import saliency_maps

QUICK_RUN = ["--budget", "5", "--steps", "20", "--steps-per-trajectory", "1", "--n-eval", "2"]


def _chunks(path) -> dict[str, list[dict]]:
    by_entity: dict[str, list[dict]] = {}
    for chunk in rr.chunk.RrdReader(path).store().stream():
        by_entity.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch().to_pydict())
    return by_entity


def test_heat_is_transparent_at_zero_and_strongest_at_one():
    maps = np.array([[0.0, 0.5], [1.0, 2.0]], np.float32)  # 2.0: clipped to 1
    rgba = heat_rgba(maps)
    assert rgba.shape == (2, 2, 4) and rgba.dtype == np.uint8
    assert rgba[0, 0, 3] == 0 and rgba[1, 0, 3] == round(255 * ALPHA_MAX)
    assert (rgba[1, 0] == rgba[1, 1]).all() and rgba[0, 1, 3] < rgba[1, 0, 3]
    frames = np.full((3, 2, 2, 3), 90, np.uint8)  # (T, H, W, 3)
    stack = np.stack([np.zeros((2, 2)), maps, maps]).astype(np.float32)  # (T, H, W)
    out = blend(frames, stack)
    assert out.shape == frames.shape and out.dtype == np.uint8
    assert (out[0] == frames[0]).all()  # nothing drawn where the map is zero
    assert out[1, 1, 0, 0] > 200 and (out[1, 0, 0] == 90).all()


def test_dfa_run_records_the_failed_rollout_s_saliency(tmp_path, nav, nav_policy):
    args = ["run", "--world", "nav2d", "--shift", "distractor_ti", "--seed", "0"]
    assert main([*args, "--saliency", "grad_cam", *QUICK_RUN, "--out", str(tmp_path)]) == 0
    (path,) = tmp_path.glob("*.rrd")
    chunks = _chunks(path)
    assert chunks["/__properties/saliency"][0]["method"] == [["grad_cam"]]
    images = [c for c in chunks["/rollouts/failed/saliency"] if "Image:buffer" in c]
    steps = [s for c in images for s in c["step"]]
    layers = [np.asarray(b, np.uint8) for c in images for b in c["Image:buffer"]]
    assert steps == list(range(20))  # one per step the demonstration has an action for
    cleared = [c for c in chunks["/rollouts/failed/saliency"] if "Clear:is_recursive" in c]
    assert [s for c in cleared for s in c["step"]] == [20]  # none over the last frame
    (fmt,) = images[0]["Image:format"][0]
    assert (fmt["width"], fmt["height"]) == (36, 36)
    # the layer is the heat of the maps of the failed rollout against the demonstration
    task, rollout = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    maps = saliency_maps(nav, nav_policy, rollout, nav.demonstrate(task), "grad_cam")
    want = heat_rgba(maps).reshape(20, -1)
    np.testing.assert_array_equal(np.stack([x.reshape(-1) for x in layers]), want)
    assert all(c["Image:draw_order"] == [[10.0]] * len(c["step"]) for c in images)  # above


def test_without_the_flag_there_is_no_layer(tmp_path):
    args = ["run", "--world", "nav2d", "--shift", "object_ti", "--seed", "0", *QUICK_RUN]
    assert main([*args, "--out", str(tmp_path)]) == 0
    (path,) = tmp_path.glob("*.rrd")
    chunks = _chunks(path)
    assert "/rollouts/failed/saliency" not in chunks and "/__properties/saliency" not in chunks


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--saliency", "lrp"], "unknown saliency method 'lrp'; accepted: integrated_gradients"),
        (
            [
                "--world",
                "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12",
                "--policy",
                "onnx:docs/examples/doorkey5x5_ppo.onnx",
                "--saliency",
                "grad_cam",
            ],
            "saliency maps need an image policy whose network they can take apart",
        ),
    ],
)
def test_a_method_or_policy_that_cannot_be_explained_is_one_line(capsys, tmp_path, args, message):
    assert main(["run", *args, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not list(tmp_path.glob("*.rrd"))
