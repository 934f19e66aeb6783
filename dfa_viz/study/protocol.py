"""A study protocol (study.toml) and the plan it gives each participant.

    seed = 0
    design = "between"                      # the paper's; or "within"
    conditions = ["none", "counterfactual"]  # of none, counterfactual, saliency, both
    saliency = "grad_cam"                    # the saliency condition's method
    kinds = ["object", "distractor", "other"]

    [tasks]                                  # tasks per shift kind in each world
    nav2d = 1
    doorkey = 1
    tabletop = 2

A *slot* is one question of the study: (world, kind, index). The object and distractor kinds
have two frozen tasks per slot, one where what changed does not matter to what the user asked
for (TI) and one where it does (TR); each participant gets one of them: TI and TR alternate
over a participant's slots (half and half) and swap from one participant to the next (every
slot TI and TR equally often over each batch of two participants). `other` has one task per
slot (its cause is outside the concepts).

The paper's study was between subjects (each participant saw one condition), and so is the
default; `within` is kept for studies that want every participant under every condition (its
answers are analysed with a mixed-effects model, since one participant's answers are not
independent: dfa_viz.study.models).

Orders are balanced in blocks: over every block of as many participants as there are slots,
each slot comes at each position once (a cyclic Latin square over a seeded order of the slots,
its rows dealt out in a seeded order per block). Conditions: `between` gives each participant
one condition, every condition once per block of len(conditions) participants; `within` gives
each slot a condition, rotating with the participant's number, so every slot is seen under
every condition equally often.
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from policy.methods import check_method
from sim import PAPER_WORLDS
from sim.core import UserError, check_seed

CONDITIONS = ("none", "counterfactual", "saliency", "both")
KINDS = ("object", "distractor", "other")
DESIGNS = ("between", "within")
# the paper's study: one task per gridworld, two on the tabletop, in sim.PAPER_WORLDS' order
PAPER_TASKS = tuple(zip(PAPER_WORLDS, (1, 1, 2), strict=True))


@dataclass(frozen=True, order=True)
class Slot:
    """One question of the study: the index-th task of `kind` in `world`."""

    world: str
    kind: str
    index: int

    @property
    def key(self) -> str:
        return f"{self.world}/{self.kind}/{self.index}"

    def shifts(self) -> tuple[str, ...]:
        """The frozen tasks' shifts: (TI, TR) for object and distractor, (other,)."""
        return ("other",) if self.kind == "other" else (f"{self.kind}_ti", f"{self.kind}_tr")


@dataclass(frozen=True)
class Protocol:
    """What a study asks: which tasks, under which conditions, in which design."""

    tasks: tuple[tuple[str, int], ...] = PAPER_TASKS
    """(world, tasks per shift kind); the paper's: one each in nav2d and DoorKey, two in the
    tabletop (12 questions per participant)."""
    conditions: tuple[str, ...] = ("none", "counterfactual")
    """What each question shows beside the failed behaviour."""
    design: str = "between"
    """between (one condition per participant: the paper's) or within (conditions rotate over
    a participant's questions)."""
    kinds: tuple[str, ...] = KINDS
    """Which shift kinds are asked about."""
    seed: int = 0
    """Picks the tasks (test task seeds seed, seed + 1, ...) and every order."""
    saliency: str = "grad_cam"
    """The saliency method of the saliency and both conditions."""
    slots: tuple[Slot, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "slots",
            tuple(Slot(w, k, i) for w, n in self.tasks for k in self.kinds for i in range(n)),
        )

    def check(self) -> Protocol:
        """Raise a one-line UserError for anything a study cannot be made from."""
        from sim import check_world_name, get_world

        check_seed(self.seed, "seed")
        if self.design not in DESIGNS:
            raise UserError(f"design is between or within, not {self.design!r}")
        if not self.conditions or len(set(self.conditions)) != len(self.conditions):
            raise UserError("conditions must name at least one condition, each once")
        for c in self.conditions:
            if c not in CONDITIONS:
                raise UserError(f"unknown condition {c!r}; accepted: {', '.join(CONDITIONS)}")
        for k in self.kinds:
            if k not in KINDS:
                raise UserError(f"unknown shift kind {k!r}; accepted: {', '.join(KINDS)}")
        if not self.kinds or len(set(self.kinds)) != len(self.kinds):
            raise UserError("kinds must name at least one shift kind, each once")
        check_method(self.saliency)
        if not self.tasks or len({w for w, _ in self.tasks}) != len(self.tasks):
            raise UserError("[tasks] must name at least one world, each once")
        for world, n in self.tasks:
            w = get_world(check_world_name(world))
            if not w.benchmark:
                raise UserError(f"{world} makes no test tasks; a study needs planted shifts")
            if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 20:
                raise UserError(f"[tasks] {world} must be a number of tasks from 1 to 20, not {n}")
        return self

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("slots")
        d["tasks"] = dict(self.tasks)
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "protocol") -> Protocol:
        known = {"tasks", "conditions", "design", "kinds", "seed", "saliency"}
        extra = sorted(set(d) - known)
        if extra:
            raise UserError(
                f"{where}: unknown key {extra[0]!r}; accepted: {', '.join(sorted(known))}"
            )
        tasks = d.get("tasks", dict(PAPER_TASKS))
        if not isinstance(tasks, dict):
            raise UserError(f"{where}: [tasks] must be a table of world = number of tasks")
        try:
            return cls(
                tasks=tuple((str(w), n) for w, n in tasks.items()),
                conditions=tuple(str(c) for c in d.get("conditions", cls.conditions)),
                design=str(d.get("design", cls.design)),
                kinds=tuple(str(k) for k in d.get("kinds", KINDS)),
                seed=d.get("seed", 0),
                saliency=str(d.get("saliency", cls.saliency)),
            ).check()
        except TypeError as e:
            raise UserError(f"{where}: {e}") from None

    @classmethod
    def load(cls, path: str | Path) -> Protocol:
        """Read and check a study.toml."""
        path = Path(path)
        try:
            raw = tomllib.loads(path.read_text())
        except OSError as e:
            raise UserError(f"{path}: cannot read the protocol ({e.strerror})") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise UserError(f"{path}: not a TOML file ({str(e).splitlines()[0]})") from None
        return cls.from_dict(raw, str(path))


@dataclass(frozen=True)
class Question:
    """One question of one participant's plan: a slot, which of its tasks, and what is shown."""

    slot: Slot
    shift: str
    """The frozen task's shift (server side only: never sent to the page)."""
    condition: str

    def to_json(self) -> dict:
        return {**asdict(self.slot), "shift": self.shift, "condition": self.condition}

    @classmethod
    def from_json(cls, d: dict) -> Question:
        return cls(Slot(d["world"], d["kind"], int(d["index"])), d["shift"], d["condition"])


def _rng(protocol: Protocol, *words: int) -> np.random.Generator:
    return np.random.default_rng([protocol.seed, *words])


def order(protocol: Protocol, number: int) -> list[Slot]:
    """Participant `number`'s slots in the order they are asked (balanced per block)."""
    slots = protocol.slots
    n = len(slots)
    base = _rng(protocol, 1).permutation(n)
    block, k = divmod(number, n)
    row = int(_rng(protocol, 2, block).permutation(n)[k])
    return [slots[int(base[(row + j) % n])] for j in range(n)]


def plan(protocol: Protocol, number: int) -> list[Question]:
    """Participant `number`'s questions (0-based number, in order of arrival)."""
    conds = protocol.conditions
    c = len(conds)
    between = conds[int(_rng(protocol, 3, number // c).permutation(c)[number % c])]
    offset = int(_rng(protocol, 4).integers(2))
    two = [s for s in protocol.slots if s.kind != "other"]  # TI and TR alternate over these
    out = []
    for slot in order(protocol, number):
        i = protocol.slots.index(slot)
        shifts = slot.shifts()
        flip = two.index(slot) if slot in two else 0
        shift = shifts[(number + offset + flip) % len(shifts)]
        condition = between if protocol.design == "between" else conds[(i + number) % c]
        out.append(Question(slot, shift, condition))
    return out
