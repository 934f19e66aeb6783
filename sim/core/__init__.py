"""The concept model shared by every world: concept space, scenes, edits, tasks, trajectories."""

from sim.core.concepts import (
    ABSENT,
    PRESENCE,
    PRESENT,
    Concept,
    ConceptSpace,
    Slot,
    UserConcept,
)
from sim.core.demonstration import check_demonstration, require_success
from sim.core.edit import EMPTY, Change, Edit, apply, apply_many, effective, single_changes
from sim.core.effector import Waypoint
from sim.core.errors import UserError
from sim.core.feedback import Feedback, Label
from sim.core.recipes import Adapting, Cloning
from sim.core.scene import Obj, Scene
from sim.core.task import (
    LAYOUTS,
    SHIFTS,
    TRAIN,
    Reward,
    Task,
    carrying_shift,
    check_layouts,
    check_seed,
    check_shift,
    draw_from_reward,
)
from sim.core.trajectory import Trajectory
from sim.core.world import RGB, ActBatch, Benchmark, Key, Paints, World

__all__ = [
    "ABSENT",
    "EMPTY",
    "LAYOUTS",
    "PRESENCE",
    "PRESENT",
    "RGB",
    "SHIFTS",
    "TRAIN",
    "ActBatch",
    "Adapting",
    "Benchmark",
    "Change",
    "Cloning",
    "Concept",
    "ConceptSpace",
    "Edit",
    "Feedback",
    "Key",
    "Label",
    "Obj",
    "Paints",
    "Reward",
    "Scene",
    "Slot",
    "Task",
    "Trajectory",
    "UserConcept",
    "UserError",
    "Waypoint",
    "World",
    "apply",
    "apply_many",
    "carrying_shift",
    "check_demonstration",
    "check_layouts",
    "check_seed",
    "check_shift",
    "draw_from_reward",
    "effective",
    "require_success",
    "single_changes",
]
