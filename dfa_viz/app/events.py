"""Session events: one frozen dataclass per user action or finished job (applying one to a run
record is dfa_viz.app.replay).

Each event writes itself as one JSON object (`to_json`, with its "type") and reads itself back
with every field checked (`from_json`: a UserError saying which field is wrong and what is
accepted). The format is version 1 of the session log: sessions written before these classes
load unchanged (fields added since are optional).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any, ClassVar

from dfa_viz.loop import (
    AdaptConfig,
)
from policy.evaluate import Score
from search import SearchResult
from sim import check_world_name
from sim.core import (
    Edit,
    Feedback,
    Label,
    UserError,
    check_seed,
    check_shift,
)

VERSION = 1
SWEEP = "sweep"  # the shift of a task the sweep found (a training task with one edit)


def _world(value: str, name: str) -> str:
    try:
        return check_world_name(value)
    except UserError as e:
        raise UserError(f"{name}: {e}") from None


def _shift(value: str, name: str) -> str:
    try:
        return check_shift(value)
    except UserError as e:
        raise UserError(f"{name}: {e}") from None


def _count(value: int, name: str) -> int:
    if value < 0:
        raise UserError(f"{name} must not be negative, got {value}")
    return value


def _get(d: dict, kind: str, key: str, types: tuple[type, ...], check=None, *, default=...):
    """d[key], of one of `types` (bool apart from int) and passing `check`; `default` when
    the key is missing and a default is given."""
    if key not in d:
        if default is not ...:
            return default
        raise UserError(f"{kind} event without {key!r}")
    value = d[key]
    if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
        names = " or ".join("null" if t is type(None) else t.__name__ for t in types)
        raise UserError(f"{kind}.{key} must be {names}, got {json.dumps(value)[:60]}")
    return check(value, f"{kind}.{key}") if check is not None and value is not None else value


@dataclass(frozen=True)
class SessionStarted:
    """The first line of a session: the format version and the world it opened on."""

    TYPE: ClassVar[str] = "session"
    world: str
    version: int = VERSION

    def to_json(self) -> dict[str, Any]:
        return {"version": self.version, "world": self.world}

    @classmethod
    def from_json(cls, d: dict) -> SessionStarted:
        version = _get(d, cls.TYPE, "version", (int,))
        if version != VERSION:
            raise UserError(f"session format version {version}; this program reads {VERSION}")
        return cls(_get(d, cls.TYPE, "world", (str,), _world), version)


@dataclass(frozen=True)
class TaskLoaded:
    """A test task was loaded: the failing task of (world, shift, seed), whose own seed is
    task_seed; or (shift "sweep", with `edit`) a failure the sweep found: training task
    task_seed with the edit made, the object it adds at `pos` when given."""

    TYPE: ClassVar[str] = "task"
    world: str
    shift: str
    seed: int
    task_seed: int
    edit: Edit | None = None
    pos: tuple[float, ...] | None = None

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "world": self.world,
            "shift": self.shift,
            "seed": self.seed,
            "task_seed": self.task_seed,
        }
        if self.edit is not None:
            d["edit"] = self.edit.to_list()
        if self.pos is not None:
            d["pos"] = list(self.pos)
        return d

    @classmethod
    def from_json(cls, d: dict) -> TaskLoaded:
        k = cls.TYPE
        world, shift = _get(d, k, "world", (str,)), _get(d, k, "shift", (str,))
        seed, task_seed = _get(d, k, "seed", (int,)), _get(d, k, "task_seed", (int,))
        edit = _get(d, k, "edit", (list,), default=None)
        pos = _get(d, k, "pos", (list,), default=None)
        if pos is not None and not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in pos
        ):
            raise UserError(f"{k}.pos must be a list of numbers, got {json.dumps(pos)[:60]}")
        if (edit is None) != (shift != SWEEP):
            raise UserError(f"{k}: a task with an edit has shift {SWEEP!r}, and only such a one")
        return cls(  # every type first, then the values
            _world(world, f"{k}.world"),
            shift if edit is not None else _shift(shift, f"{k}.shift"),
            check_seed(seed, f"{k}.seed"),
            check_seed(task_seed, f"{k}.task_seed"),
            None if edit is None else Edit.from_list(edit),
            None if pos is None else tuple(float(v) for v in pos),
        )


@dataclass(frozen=True)
class Judged:
    """The user's judgement of the base policy's rollout."""

    TYPE: ClassVar[str] = "judgement"
    failed: bool

    def to_json(self) -> dict[str, Any]:
        return {"failed": self.failed}

    @classmethod
    def from_json(cls, d: dict) -> Judged:
        return cls(_get(d, cls.TYPE, "failed", (bool,)))


@dataclass(frozen=True)
class Demonstrated:
    """The demonstration, saved as `file` in the session folder; source: how it was given."""

    TYPE: ClassVar[str] = "demonstration"
    file: str
    source: str

    def to_json(self) -> dict[str, Any]:
        return {"file": self.file, "source": self.source}

    @classmethod
    def from_json(cls, d: dict) -> Demonstrated:
        return cls(_get(d, cls.TYPE, "file", (str,)), _get(d, cls.TYPE, "source", (str,)))


@dataclass(frozen=True)
class Searched:
    """The counterfactual search's result (every candidate tried)."""

    TYPE: ClassVar[str] = "search"
    result: SearchResult

    def to_json(self) -> dict[str, Any]:
        return self.result.to_json()

    @classmethod
    def from_json(cls, d: dict) -> Searched:
        _get(d, cls.TYPE, "size", (int, type(None)), _count)
        _get(d, cls.TYPE, "max_size", (int,), _count)
        _get(d, cls.TYPE, "counterfactuals", (list,))
        _get(d, cls.TYPE, "tried", (list,))
        return cls(SearchResult.from_json(d))


@dataclass(frozen=True)
class TieChosen:
    """The user picked another of the minimal edits."""

    TYPE: ClassVar[str] = "tie"
    index: int

    def to_json(self) -> dict[str, Any]:
        return {"index": self.index}

    @classmethod
    def from_json(cls, d: dict) -> TieChosen:
        return cls(_get(d, cls.TYPE, "index", (int,), _count))


@dataclass(frozen=True)
class Marked:
    """An edited concept marked TI (with the values that are fine) or TR."""

    TYPE: ClassVar[str] = "mark"
    label: Label

    def to_json(self) -> dict[str, Any]:
        return self.label.to_dict()

    @classmethod
    def from_json(cls, d: dict) -> Marked:
        for key in ("slot", "concept", "label"):
            _get(d, cls.TYPE, key, (str,))
        acceptable = _get(d, cls.TYPE, "acceptable", (list,))
        if d["label"] not in ("TI", "TR"):
            raise UserError(f"a mark is TI or TR, not {d['label']!r}")
        if not all(isinstance(v, str) for v in acceptable):
            raise UserError(f"mark.acceptable must be a list of names, got {acceptable!r}"[:100])
        return cls(Label.from_dict(d))


@dataclass(frozen=True)
class Finetuned:
    """An adaptation: the feedback, the files it wrote and the scores of both policies.

    before/after are None in sessions written before scores were kept: applying the event
    scores the base policy and the saved checkpoint again.
    """

    TYPE: ClassVar[str] = "finetune"
    feedback: Feedback
    n_augmented: int
    losses: tuple[float, ...]
    rollout_file: str
    policy_dir: str
    config: AdaptConfig | None = None
    """How it adapted (None in sessions written before it was kept)."""
    before: Score | None = None
    after: Score | None = None

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "feedback": self.feedback.to_list(),
            "n_augmented": self.n_augmented,
            "losses": [round(v, 6) for v in self.losses],
            "rollout_file": self.rollout_file,
            "policy_dir": self.policy_dir,
        }
        if self.config is not None:
            d["adapt"] = dataclasses.asdict(self.config)
        if self.before is not None and self.after is not None:
            d |= {
                "success_before": self.before.on_shift,
                "success_after": self.after.on_shift,
                "success_all_before": self.before.on_all,
                "success_all_after": self.after.on_all,
                "scores": {"before": self.before.to_json(), "after": self.after.to_json()},
            }
        return d

    @classmethod
    def from_json(cls, d: dict) -> Finetuned:
        k = cls.TYPE
        losses = _get(d, k, "losses", (list,))
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in losses):
            raise UserError("finetune.losses must be a list of numbers")
        scores = _get(d, k, "scores", (dict,), default=None)
        adapt = _get(d, k, "adapt", (dict,), default=None)
        try:
            before = None if scores is None else Score.from_json(scores["before"])
            after = None if scores is None else Score.from_json(scores["after"])
            config = None if adapt is None else AdaptConfig.from_dict(adapt).check()
        except (KeyError, TypeError, ValueError) as e:
            raise UserError(f"finetune event is malformed ({type(e).__name__}: {e})") from None
        return cls(
            Feedback.from_list(_get(d, k, "feedback", (list,))),
            _get(d, k, "n_augmented", (int,), _count),
            tuple(float(v) for v in losses),
            _get(d, k, "rollout_file", (str,)),
            _get(d, k, "policy_dir", (str,)),
            config,
            before,
            after,
        )


Event = TaskLoaded | Judged | Demonstrated | Searched | TieChosen | Marked | Finetuned
TYPES: dict[str, type] = {
    cls.TYPE: cls
    for cls in (
        SessionStarted,
        TaskLoaded,
        Judged,
        Demonstrated,
        Searched,
        TieChosen,
        Marked,
        Finetuned,
    )
}


def from_json(d: Any) -> SessionStarted | Event:
    """The event a session line holds (its "type" says which); UserError if malformed."""
    if not isinstance(d, dict):
        raise UserError(f"expected a JSON object, got {type(d).__name__}")
    kind = d.get("type")
    if not isinstance(kind, str) or kind not in TYPES:
        shown = repr(kind) if isinstance(kind, str) else json.dumps(kind)[:60]
        raise UserError(f"unknown event type {shown}; accepted: {', '.join(TYPES)}")
    return TYPES[kind].from_json(d)
