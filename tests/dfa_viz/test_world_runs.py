"""`dfa run` on the worlds beyond the paper's: a plain gymnasium environment through
sim.gymenv (docs/examples/grid_reacher.py), the Fetch and robosuite tasks and MiniGrid's
missions read by the simulated user."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import sim
from dfa_viz.cli import main
from dfa_viz.users import SimulatedUser
from sim.core import PRESENCE, Change, Edit

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"


def test_what_is_not_a_fetch_task_is_one_line(capsys):
    assert main(["run", "--world", "fetch:FetchJuggle-v4"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a Fetch task; accepted: FetchPickAndPlace-v4" in err[0]


@pytest.mark.parametrize(
    "world, said",
    [
        ("robosuite:Juggle", "not a robosuite task offered here; accepted: Lift, Stack"),
        ("robosuite:Lift:robot=Robby", "unknown option 'robot=Robby'; accepted: robot=Panda|"),
        ("robosuite:Lift:camera=nope", "no camera 'nope' in the model; accepted: frontview, "),
    ],
)
def test_what_robosuite_does_not_offer_is_one_line(world, said, capsys):
    """An unknown env, robot or camera: one line naming what is accepted, exit 2."""
    assert main(["run", "--world", world]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err


@pytest.mark.slow
def test_dfa_run_diagnoses_and_adapts_a_policy_in_the_gymnasium_world(
    tmp_path, monkeypatch, capsys
):
    """The base policy (cloned on first use, cached under DFA_CACHE) fails on a recoloured
    target; the counterfactual changes the target's colour; TI feedback, variants and
    finetuning raise its success on the shift."""
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.setenv("DFA_CACHE", str(tmp_path / "cache"))
    args = ["run", "--world", "grid_reacher:reacher", "--shift", "object_ti", "--seed", "0"]
    assert main([*args, "--json", "--out", str(tmp_path / "rec")]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["world"] == "gridreacher" and report["failed"]
    changed = {(c["slot"], c["concept"]) for edit in report["counterfactual"] for c in edit}
    assert changed == {("target", "colour")}, report["counterfactual"]
    assert [f["label"] for f in report["feedback"]] == ["TI"] and report["augmented"] > 0
    assert report["success_after"] - report["success_before"] >= 0.3, report
    assert Path(report["recording"]) == tmp_path / "rec" / "gridreacher-object_ti-seed0.rrd"
    assert Path(report["recording"]).stat().st_size > 0


def test_the_simulated_user_reads_a_minigrid_mission():
    """The goal named by Dynamic-Obstacles' mission and both of RedBlueDoors' door colours
    are labelled TR."""
    w = sim.get_world("minigrid:MiniGrid-Dynamic-Obstacles-5x5-v0")
    task = w.test_task(w.shifts[0], 0)
    goal = next(o for o in task.scene.objects if o.slot.startswith("goal") and o.present)
    removed = Edit.of(Change(goal.slot, PRESENCE, "present", "absent"))
    assert SimulatedUser(w).label(task, removed).labels[0].relevant
    w = sim.get_world("minigrid:MiniGrid-RedBlueDoors-6x6-v0")
    for shift in w.shifts:
        task = w.test_task(shift, 0)
        for door in (o for o in task.scene.objects if o.slot.startswith("door") and o.present):
            edit = Edit.of(Change(door.slot, "colour", door.value("colour"), "green"))
            assert SimulatedUser(w).label(task, edit).labels[0].relevant
