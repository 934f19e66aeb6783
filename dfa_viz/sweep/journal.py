"""`dfa sweep`'s append-only results: OUT/results.jsonl, one JSON line per unit of work, written
as each unit finishes, so that `--resume` runs only the units not yet in it.

The first line says whose sweep it is (world, policy, tasks, seed, sizes, pairs, expert); every
other line is one unit's result ({"what": "singles" | "pairs", "unit": i, "of": digest, ...}),
the digest naming the unit's tasks and cells, so a file that another sweep (or another cut of
the work into units) wrote is refused rather than mixed in. Each line goes out whole and fsynced
(sim.core.files.append_bytes). A last line without its newline is what a killed process leaves:
it is left out, with a note, and cut off before the next line is appended. Anything else that
does not read back (a garbled line in the middle, a header of another sweep) is bad input: one
line, and the file is left as it is.

A unit's outcomes go through JSON exactly (floats as Python writes them, which read back to the
same bits; nan as null), so a resumed sweep gives the files a whole one gives.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from search.sweep import Outcome, Reference, Unit, UnitResult
from sim.core import UserError, files

RESULTS = "results.jsonl"
FORMAT = 1
SINGLES, PAIRS = "singles", "pairs"


def kind(unit: Unit) -> str:
    return PAIRS if unit.pairs else SINGLES


def digest(unit: Unit) -> str:
    """Names a unit's work: its first task, its tasks' seeds and its pair cells."""
    text = json.dumps([unit.first, [t.seed for t in unit.tasks], [list(p) for p in unit.pairs]])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _num(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def _float(x: float | None) -> float:
    return math.nan if x is None else float(x)


def _key(key):
    """A cell (3 strings) or a pair (2 cells) back from JSON lists."""
    if isinstance(key[0], list):
        return tuple(tuple(k) for k in key)
    return tuple(key)


def encode(result: UnitResult) -> dict:
    return {
        "rollouts": result.rollouts,
        "frames": result.frames,
        "references": [[r.task, r.failed, r.expert_failed] for r in result.references],
        "outcomes": [
            [
                o.task,
                o.key,
                o.failed,
                o.solvable,
                _num(o.deviation),
                _num(o.expert_deviation),
                o.place,
                None if o.pos is None else [float(x) for x in o.pos],
            ]
            for o in result.outcomes
        ],
    }


def decode(unit: int, data: dict) -> UnitResult:
    refs = tuple(Reference(int(t), bool(f), e) for t, f, e in data["references"])
    outcomes = tuple(
        Outcome(
            int(task),
            _key(key),
            bool(failed),
            solvable,
            _float(dev),
            _float(edev),
            int(place),
            None if pos is None else tuple(float(x) for x in pos),
        )
        for task, key, failed, solvable, dev, edev, place, pos in data["outcomes"]
    )
    return UnitResult(unit, refs, outcomes, int(data["rollouts"]), int(data["frames"]))


@dataclass
class Journal:
    """The results file of one sweep: the units it already holds, and appending new ones."""

    path: Path
    header: dict
    done: dict[tuple[str, int], tuple[str, UnitResult]] = field(default_factory=dict)
    note: str | None = None
    """Set when a last line cut short was left out."""

    @classmethod
    def start(cls, path: Path, header: dict) -> Journal:
        """A fresh file holding the header alone (written atomically; an older one replaced)."""
        files.write_text(path, json.dumps({"dfa_sweep": FORMAT, **header}) + "\n")
        return cls(path, header)

    @classmethod
    def resume(cls, path: Path, header: dict) -> Journal:
        """The file as a killed or finished sweep left it; bad input raises a UserError and
        leaves it untouched. A last line cut short is left out (`note`) and cut off the file."""
        if not path.is_file():
            raise UserError(f"--resume: there is no {path} to resume (run without --resume)")
        raw = path.read_bytes()
        whole = raw[: raw.rfind(b"\n") + 1]
        try:
            lines = whole.decode().splitlines()
        except UnicodeDecodeError:
            raise UserError(f"--resume: {path} is not a sweep's results file (not text)") from None
        head = _line(path, lines, 0) if lines else None
        if not isinstance(head, dict) or head.get("dfa_sweep") != FORMAT:
            raise UserError(f"--resume: {path} is not a results file of this version's dfa sweep")
        theirs = {k: v for k, v in head.items() if k != "dfa_sweep"}
        if theirs != header:
            diff = ", ".join(
                f"{k} {theirs.get(k)!r} (now {header.get(k)!r})"
                for k in sorted(set(theirs) | set(header))
                if theirs.get(k) != header.get(k)
            )
            raise UserError(
                f"--resume: {path} holds another sweep: {diff}; give the same options, or "
                "another --out, or leave out --resume to start afresh"
            )
        journal = cls(path, header)
        for n in range(1, len(lines)):
            rec = _line(path, lines, n)
            try:
                what, unit, of = rec["what"], int(rec["unit"]), str(rec["of"])
                if what not in (SINGLES, PAIRS):
                    raise ValueError(what)
                journal.done.setdefault((what, unit), (of, decode(unit, rec["result"])))
            except (KeyError, TypeError, ValueError):
                raise UserError(
                    f"--resume: {path}, line {n + 1}: not a unit's result; the file is left "
                    "as it is"
                ) from None
        if len(whole) < len(raw):
            journal.note = (
                f"{path}: its last line was cut short (a run stopped while writing it); "
                "that unit runs again"
            )
            os.truncate(path, len(whole))
        return journal

    def get(self, unit: Unit) -> UnitResult | None:
        """The unit's result if the file holds it (for this very unit), else None."""
        got = self.done.get((kind(unit), unit.index))
        if got is None:
            return None
        of, result = got
        if of != digest(unit):
            raise UserError(
                f"--resume: {self.path} holds {kind(unit)} unit {unit.index} of other tasks "
                "or cells (another version cut the work differently); leave out --resume to "
                "start afresh"
            )
        return result

    def add(self, unit: Unit, result: UnitResult) -> None:
        """Append the unit's line, whole and fsynced."""
        rec = {"what": kind(unit), "unit": unit.index, "of": digest(unit), "result": encode(result)}
        files.append_bytes(self.path, (json.dumps(rec, allow_nan=False) + "\n").encode())
        self.done[(kind(unit), unit.index)] = (digest(unit), result)


def _line(path: Path, lines: list[str], n: int):
    try:
        return json.loads(lines[n])
    except json.JSONDecodeError:
        where = "the header" if n == 0 else f"line {n + 1} of {len(lines)}"
        raise UserError(
            f"--resume: {path}, {where}: garbled (not a whole JSON line); the file is left as it is"
        ) from None
