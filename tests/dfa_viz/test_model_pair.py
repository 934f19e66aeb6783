"""The explainer benchmark's model pair on one seed: the loop's finetuned policy is the base
policy taught to ignore the distractor, by behaviour, and every method's shares are read for
both on the same frames."""

from __future__ import annotations

import csv
import io
import math

import pytest

from dfa_viz.cli import main
from dfa_viz.experiment.model_pair import COLUMNS, pair_rows, share
from policy.concept_saliency import READINGS
from policy.methods import METHOD_NAMES

pytestmark = pytest.mark.slow


def test_share_counts_the_positive_part_inside_the_mask():
    import numpy as np

    maps = np.array([[[3.0, 1.0], [-2.0, 0.0]]])  # (1, 2, 2)
    mask = np.array([[[True, False], [True, False]]])
    assert share(maps, mask) == 0.75  # 3 of 4; the negative pixel counts as nothing
    assert math.isnan(share(np.zeros((1, 2, 2)), mask))


def test_the_pair_differs_by_behaviour_and_each_method_reads_both():
    rows = pair_rows(0)
    assert {(r["method"], r["reading"]) for r in rows} == {
        (m, r) for m in METHOD_NAMES for r in READINGS
    }
    (moved_base,) = {r["moved_base"] for r in rows}
    (moved_tuned,) = {r["moved_tuned"] for r in rows}
    # measured 0.23 against 0.016: removing the distractor moves only the base policy
    assert moved_base > 4 * moved_tuned, (moved_base, moved_tuned)
    for r in rows:
        assert 0.0 <= r["share_base"] <= 1.0 and 0.0 <= r["share_tuned"] <= 1.0, r


def test_the_command_writes_its_rows_and_table(tmp_path):
    assert main(["experiment", "pair", "--seeds", "1", "--out", str(tmp_path)]) == 0
    rows = list(csv.DictReader(io.StringIO((tmp_path / "pair.csv").read_text())))
    assert tuple(rows[0]) == COLUMNS and len(rows) == len(METHOD_NAMES) * len(READINGS)
    text = (tmp_path / "table.md").read_text()
    assert "on 1 of 1" in text and all(m in text for m in METHOD_NAMES)
    assert main(["experiment", "pair", "--seeds", "0", "--out", str(tmp_path)]) == 2
