"""The explainer benchmark's model pair: the loop's finetuned policy is the base policy taught
to ignore the cause, by behaviour, and every method's shares are read for both on the same
frames; the table keeps each (world, shift) apart."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from dfa_viz.cli import main
from dfa_viz.experiment.model_pair import (
    COLUMNS,
    PAIR_SHIFTS,
    pair_rows,
    pair_worlds,
    share,
    table,
    undo_of,
)
from policy.concept_saliency import READINGS
from policy.methods import METHOD_NAMES
from sim import get_world
from sim.core import Change, Edit


def test_share_counts_the_positive_part_inside_the_mask():
    maps = np.array([[[3.0, 1.0], [-2.0, 0.0]]])  # (1, 2, 2)
    mask = np.array([[[True, False], [True, False]]])
    assert share(maps, mask) == 0.75  # 3 of 4; the negative pixel counts as nothing
    assert math.isnan(share(np.zeros((1, 2, 2)), mask))


def test_the_undo_keeps_only_the_changes_to_the_causes_concept():
    space = get_world("doorkey").space
    lava = Change("lava1", "presence", "present", "absent")
    door = Change("door", "colour", "blue", "yellow")
    # lava0's cause covers every lava tile: the change of lava1 undoes it, the door's does not
    assert undo_of(space, ("lava0", "presence"), Edit.of(lava, door)) == Edit.of(lava)
    assert undo_of(space, ("door", "colour"), Edit.of(lava, door)) == Edit.of(door)
    assert undo_of(space, ("key", "colour"), Edit.of(lava, door)) is None


def _row(world, shift, seed, task, moved_base, moved_tuned, apart):
    return {
        "world": world,
        "shift": shift,
        "seed": seed,
        "task": task,
        "cause": "x.presence",
        "undo": "-" if math.isnan(moved_base) else "x.presence: present -> absent",
        "method": "occlusion",
        "reading": "abs",
        "share_base": 0.3,
        "share_tuned": 0.1,
        "moved_base": moved_base,
        "moved_tuned": moved_tuned,
        "apart": apart,
    }


def test_the_table_counts_each_world_and_shift_on_its_own():
    nan = float("nan")
    rows = [
        _row("nav2d", "distractor_ti", 0, "a", 0.5, 0.1, 1),
        _row("nav2d", "distractor_ti", 1, "a", 0.5, 0.1, 0),
        _row("doorkey", "object_ti", 0, "b", 0.1, 0.4, 1),  # finetuned moves more: no verdict
        _row("doorkey", "object_ti", 1, "c", nan, nan, 1),  # the cause not undone: no verdict
        _row("doorkey", "object_ti", 2, "c", 0.6, 0.2, 1),
    ]
    text = table(rows, "dfa experiment pair")
    assert "| nav2d | distractor_ti | 2 (1) | 2 of 2 | occlusion | abs | 1 of 2 seeds |" in text
    assert "| doorkey | object_ti | 3 (2) | 1 of 3 | occlusion | abs | 1 of 1 seeds |" in text
    assert "| doorkey | object_ti | 1 | c | - | - | - | no |" in text


@pytest.mark.parametrize(
    "option", [("--world", "tabletop"), ("--shift", "object_tr"), ("--seeds", "0")]
)
def test_a_bad_option_is_one_line_and_writes_nothing(tmp_path, capsys, option):
    out = tmp_path / "pair"
    assert main(["experiment", "pair", *option, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    accepted = {"--world": pair_worlds(), "--shift": PAIR_SHIFTS, "--seeds": ("at least 1",)}
    assert all(a in err[0] for a in accepted[option[0]]), err
    assert not out.exists()


@pytest.mark.slow
def test_the_doorkey_object_pair_differs_by_behaviour():
    # seed 1: the door recoloured (seed 0's key is a near thing: 0.050 against 0.023 on one
    # torch thread, 0.052 for the finetuned policy on two)
    rows = pair_rows(1, world_name="doorkey", shift="object_ti", methods=("grad_cam",))
    assert {(r["method"], r["reading"]) for r in rows} == {("grad_cam", r) for r in READINGS}
    (undo,) = {r["undo"] for r in rows}
    (cause,) = {r["cause"] for r in rows}
    assert cause.endswith(".colour") and undo.startswith(f"{cause}:"), (cause, undo)
    (moved_base,) = {r["moved_base"] for r in rows}
    (moved_tuned,) = {r["moved_tuned"] for r in rows}
    # measured 0.917 against 0.006 (action probabilities): the colour matters to the base only
    assert moved_base > 5 * moved_tuned, (moved_base, moved_tuned)


@pytest.mark.slow
def test_the_command_writes_its_rows_and_table(tmp_path):
    out = ["--out", str(tmp_path)]
    args = ["experiment", "pair", "--world", "nav2d", "--shift", "distractor_ti", "--seeds", "1"]
    assert main([*args, *out]) == 0
    rows = list(csv.DictReader(io.StringIO((tmp_path / "pair.csv").read_text())))
    assert tuple(rows[0]) == COLUMNS and len(rows) == len(METHOD_NAMES) * len(READINGS)
    (moved_base,) = {float(r["moved_base"]) for r in rows}
    (moved_tuned,) = {float(r["moved_tuned"]) for r in rows}
    # measured 0.23 against 0.016: removing the distractor moves only the base policy
    assert moved_base > 4 * moved_tuned, (moved_base, moved_tuned)
    assert {r["undo"] for r in rows} == {"distractor.presence: present -> absent"}
    text = (tmp_path / "table.md").read_text()
    assert "| nav2d | distractor_ti | 1 (1) | 1 of 1 |" in text
    assert all(m in text for m in METHOD_NAMES)
    assert "--world nav2d --shift distractor_ti --seeds 1" in text
