"""What a MiniGrid mission names is task-relevant: the goal's presence, every named object and
colour; shifts never recolour a named object, the instruction says what is open, and a mission
whose target the frames do not show says so once."""

from __future__ import annotations

import pytest

import sim
from sim.core import PRESENCE, UserError
from sim.minigrid.mission import Mission, Named, named


def world(env_id: str):
    return sim.get_world(f"minigrid:{env_id}")


@pytest.mark.parametrize(
    ("text", "names"),
    [
        ("get to the green goal square", [Named("goal", "green")]),
        ("open the red door then the blue door", [Named("door", "red"), Named("door", "blue")]),
        ("go get a blue key", [Named("key", "blue")]),
        ("pick up a ball", [Named("ball", None)]),
        ("put the grey key next to the green key", [Named("key", "grey"), Named("key", "green")]),
        (
            "get the yellow key from the grey room, unlock the yellow door and go to the goal",
            [
                Named("key", "yellow"),
                Named("door", "grey"),
                Named("door", "yellow"),
                Named("goal", None),
            ],
        ),
        ("go to the matching object at the end of the hallway", []),
        ("traverse the rooms to get to the goal", [Named("goal", None)]),
    ],
)
def test_a_mission_names_its_objects(text, names):
    assert list(named(text)) == names


def test_the_goals_presence_is_relevant_in_every_task():
    """Dynamic-Obstacles: removing the goal changes the task (it was labelled TI)."""
    w = world("MiniGrid-Dynamic-Obstacles-5x5-v0")
    tasks = [w.train_task(0)] + [w.test_task(shift, s) for shift in w.shifts for s in range(2)]
    for task in tasks:
        goal = next(o for o in task.scene.objects if o.slot.startswith("goal") and o.present)
        assert task.reward.is_relevant(goal.slot, PRESENCE), task.reward.instruction
        assert task.reward.is_relevant(goal.slot, "colour")  # "the green goal square"


def test_red_blue_doors_are_never_called_irrelevant():
    """Both door colours are named: no TI object shift (one line), no "whatever the door's
    colour", and R' makes a door's colour TR."""
    w = world("MiniGrid-RedBlueDoors-6x6-v0")
    assert "object_ti" not in w.shifts
    with pytest.raises(UserError, match="no TI object shift") as err:
        w.test_task("object_ti", 0)
    assert "\n" not in str(err.value)
    for shift in w.shifts:
        task = w.test_task(shift, 0)
        assert "whatever the door" not in task.reward.instruction
        doors = [o for o in task.scene.objects if o.slot.startswith("door") and o.present]
        assert {o.value("colour") for o in doors} == {"red", "blue"}
        for door in doors:
            assert task.reward.is_relevant(door.slot, "colour")
        assert len(w.notes(task)) == 1 and "names the target" in w.notes(task)[0]


def test_go_to_door_keeps_the_named_door_and_its_colour():
    """object_ti recolours only doors the mission does not name, never into the named colour,
    and the instruction says so; the target is in the text (one note)."""
    w = world("MiniGrid-GoToDoor-5x5-v0")
    for seed in range(6):
        task = w.test_task("object_ti", seed)
        m = Mission.of(task.reward.instruction.split(" (")[0])
        (target,) = [n for n in m.names if n.kind == "door"]
        base = w.layout_scene(int(task.scene.agent[0]))
        for o, b in zip(task.scene.objects, base.objects, strict=True):
            if not o.present or not o.slot.startswith("door"):
                continue
            if b.value("colour") == target.colour:  # the named door: as it was, relevant
                assert o.value("colour") == target.colour
                assert task.reward.is_relevant(o.slot, "colour")
            else:
                assert o.value("colour") != target.colour
        assert "whatever the door's colour" not in task.reward.instruction
        assert f"any colour but {target.colour}" in task.reward.instruction
        assert any("names the target" in line for line in w.notes(task))


def test_fresh_tasks_keep_the_tasks_mission():
    """Fetch's and GoToDoor's missions differ between layouts: fresh tasks come only from
    layouts whose mission names the same objects as the same slots, so they carry the task's
    R' (and the shift's colour on a slot the mission leaves open)."""
    for env_id in ("MiniGrid-Fetch-5x5-N2-v0", "MiniGrid-GoToDoor-5x5-v0"):
        w = world(env_id)
        task = w.test_task("object_ti", 0)
        slot, concept = task.cause
        colour = task.scene.obj(slot).value(concept)
        names = Mission.of(w.layouts.get(int(task.scene.agent[0]))[0].mission).names
        for fresh in w.fresh_tasks(task, 4, seed=0, shifted=True):
            m = Mission.of(w.layouts.get(int(fresh.scene.agent[0]))[0].mission)
            assert m.names == names and fresh.reward == task.reward
            assert m.relevant(w.space, w.layout_scene(int(fresh.scene.agent[0]))) == (
                task.reward.relevant
            )
            assert fresh.scene.obj(slot).value(concept) == colour


def test_a_mission_that_takes_any_ball_makes_no_ti_distractor():
    w = world("BabyAI-OneRoomS8-v0")  # "pick up the ball"
    assert "distractor_ti" not in w.shifts
    with pytest.raises(UserError, match="takes any ball"):
        w.test_task("distractor_ti", 0)


def test_a_distractor_never_takes_a_named_colour():
    w = world("BabyAI-GoToRedBallNoDists-v0")  # "go to the red ball"
    for seed in range(4):
        task = w.test_task("distractor_ti", seed)
        assert task.scene.obj(w.distractor).value("colour") != "red"
        assert "red" not in task.reward.allowed_values(w.distractor, "colour")
        assert "no other red ball" in task.reward.instruction


def test_a_corridor_with_no_room_offers_only_the_shifts_it_can_make():
    """KeyCorridorS3R1's agent starts where no free cell is in reach and every free cell is on
    the expert's path: no extra ball and no other start; the recolouring shift still works,
    and asking for the others says why in one line."""
    w = world("MiniGrid-KeyCorridorS3R1-v0")
    assert w.shifts == ("object_ti",)
    assert w.test_task("object_ti", 0).shift == "object_ti"
    for shift, why in (("distractor_ti", "off the expert's path"), ("other", "start from")):
        with pytest.raises(UserError, match=f"makes no {shift} tasks .*{why}.*accepted: object_ti"):
            w.test_task(shift, 0)
