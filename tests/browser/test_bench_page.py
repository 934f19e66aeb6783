"""`dfa bench`'s page figures come from the real page in Chromium, through to finetuning."""

from dfa_viz.bench.page import bench_page


def test_the_page_benchmark_runs_through_finetuning():
    out = bench_page(loads=1, moves=3, finetune=True)
    assert 0 < out["page_load_to_interactive_s"] <= out["page_load_to_diagnosis_drawn_s"]
    assert 0 < out["slider_to_images_ms_median"] <= out["slider_to_images_ms_max"]
    assert out["nav2d_finetune_round_trip_s"] > 0 and out["finetune_steps"] > 0
    before, after = out["nav2d_success_before_after"]
    assert 0 <= before <= 1 and 0 <= after <= 1  # learning is asserted over many tasks elsewhere
