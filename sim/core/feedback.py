"""The user's feedback on a counterfactual edit: each edited concept marked TI or TR."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sim.core.errors import UserError


@dataclass(frozen=True)
class Label:
    """One edited (slot, concept), marked task-irrelevant or not.

    relevant: True = task-relevant (TR): the policy is right to care; no augmentation.
    acceptable: for TI, the instantiations the user accepts (augmentation draws from these);
        for presence, ("present", "absent") or a subset.
    """

    slot: str
    concept: str
    relevant: bool
    acceptable: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "slot": self.slot,
            "concept": self.concept,
            "label": "TR" if self.relevant else "TI",
            "acceptable": list(self.acceptable),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Label:
        try:
            if d["label"] not in ("TI", "TR"):
                raise UserError(f"label must be 'TI' or 'TR', not {d['label']!r}")
            return cls(
                str(d["slot"]),
                str(d["concept"]),
                d["label"] == "TR",
                tuple(str(v) for v in d.get("acceptable", ())),
            )
        except (KeyError, TypeError) as e:
            raise UserError(
                f"malformed label {d!r}: needs slot, concept, label (TI|TR), acceptable"
            ) from e


@dataclass(frozen=True)
class Feedback:
    """All labels the user gave for one counterfactual (empty when there was none)."""

    labels: tuple[Label, ...] = ()

    @property
    def irrelevant(self) -> tuple[Label, ...]:
        return tuple(lab for lab in self.labels if not lab.relevant)

    def to_list(self) -> list[dict[str, Any]]:
        return [lab.to_dict() for lab in self.labels]

    @classmethod
    def from_list(cls, items: list[dict[str, Any]]) -> Feedback:
        return cls(tuple(Label.from_dict(d) for d in items))
