"""A study's answers on disk: who took part, in which order, and every answer they gave.

    DIR/participants.jsonl     one line per participant, in order of arrival: {"id", "number"}
    DIR/answers/<id>.jsonl     the first line the participant's plan (Question.to_json, in
                               order); then one line per answer (Answer.to_json, with its
                               provenance: `via` "page" when the study page wrote it, the
                               page session's id, the seconds on the question)

Every line is written, flushed and fsynced before `append` returns (the page moves on only
then); a last line cut short by a crash was never acknowledged and is dropped on reading. A
participant's plan is fixed on arrival, so a crash resumes at the first unanswered question.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from dfa_viz.study.protocol import Protocol, Question, plan
from sim.core import UserError

PARTICIPANTS = "participants.jsonl"
ANSWERS = "answers"
ID_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,24}")


def check_id(pid: str) -> str:
    """An anonymous participant code: 1 to 24 letters, digits, '-' or '_'."""
    pid = pid.strip()
    if not ID_PATTERN.fullmatch(pid):
        raise UserError(
            "a participant code is 1 to 24 letters, digits, - or _ (a code such as P07, "
            "never a name)"
        )
    return pid


def append(path: Path, doc: dict) -> None:
    """Append one JSON line durably (a torn last line from a crash is cut off first)."""
    line = (json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n").encode()
    new = not path.exists()
    with open(path, "ab+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        f.seek(0)
        data = f.read()
        cut = data.rfind(b"\n") + 1
        if cut != len(data):
            f.truncate(cut)
        f.write(line)
        f.flush()
        os.fsync(f.fileno())
    if new:
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def read_lines(path: Path) -> list[dict]:
    """The complete JSON lines of a file (a torn last line dropped); [] when it is missing."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return []
    out = []
    lines = data.split(b"\n")
    for i, raw in enumerate(lines[:-1], start=1):  # the last piece has no newline: torn
        try:
            out.append(json.loads(raw))
        except (ValueError, RecursionError):
            raise UserError(f"{path}:{i}: not a JSON line") from None
    return out


@dataclass(frozen=True)
class Answer:
    """One answer: what a participant named as the cause and whether it should matter."""

    position: int
    """Which question of the participant's plan (0-based)."""
    task: str
    """The frozen task's id (tasks/<id>)."""
    selected: tuple[str, ...]
    """The concepts named as the cause (e.g. "goal.colour"); empty with `none`."""
    none: bool
    """"The cause is not among these concepts"."""
    matters: bool
    """Should it matter for what the participant asked for (True: yes, it matters; False with
    `none`, where the page does not ask)."""
    duration_s: float
    """Time on the question: from the question shown to the answer given, in seconds."""
    via: str = "direct"
    """How the answer came: "page" (given on the study page, StudyPage.submit) or "direct"
    (written through Store.answer by other code: a script, a test); "unknown" in files written
    before answers said so."""
    session: str = ""
    """The page session (one browser tab's connection) that gave it; empty when not via the
    page. A participant who resumes after a crash answers in a new session."""

    def to_json(self) -> dict:
        return {"type": "answer", **asdict(self), "selected": list(self.selected)}

    @classmethod
    def from_json(cls, d: dict) -> Answer:
        return cls(
            int(d["position"]),
            str(d["task"]),
            tuple(str(s) for s in d["selected"]),
            bool(d["none"]),
            bool(d["matters"]),
            float(d["duration_s"]),
            str(d.get("via", "unknown")),
            str(d.get("session", "")),
        )


class Store:
    """The answers of one study folder; safe to use from many page threads at once."""

    def __init__(self, folder: Path, protocol: Protocol) -> None:
        self.folder = Path(folder)
        self.protocol = protocol
        (self.folder / ANSWERS).mkdir(exist_ok=True)
        self._lock = threading.Lock()

    def _path(self, pid: str) -> Path:
        return self.folder / ANSWERS / f"{check_id(pid)}.jsonl"

    def participants(self) -> list[dict]:
        return read_lines(self.folder / PARTICIPANTS)

    def join(self, pid: str) -> tuple[int, list[Question], list[Answer]]:
        """The participant's number, plan and answers so far (a newcomer is numbered and
        planned here, durably, before anything is shown)."""
        pid = check_id(pid)
        with self._lock:
            path = self._path(pid)
            lines = read_lines(path)
            if not lines:
                known = {p["id"]: p["number"] for p in self.participants()}
                number = known.get(pid, len(known))
                if pid not in known:
                    append(self.folder / PARTICIPANTS, {"id": pid, "number": number})
                questions = plan(self.protocol, number)
                append(
                    path,
                    {
                        "type": "participant",
                        "id": pid,
                        "number": number,
                        "plan": [q.to_json() for q in questions],
                        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
                    },
                )
                return number, questions, []
        return self.read(pid)

    def read(self, pid: str) -> tuple[int, list[Question], list[Answer]]:
        path = self._path(pid)
        lines = read_lines(path)
        if not lines or lines[0].get("type") != "participant":
            raise UserError(f"{path}: no participant header")
        try:
            questions = [Question.from_json(q) for q in lines[0]["plan"]]
            answers = [Answer.from_json(d) for d in lines[1:] if d.get("type") == "answer"]
        except (KeyError, TypeError, ValueError) as e:
            raise UserError(f"{path}: a malformed line ({e})") from None
        return int(lines[0]["number"]), questions, answers

    def answer(self, pid: str, answer: Answer) -> None:
        """Write the answer durably; it must be the next unanswered question's."""
        with self._lock:
            _, questions, answers = self.read(pid)
            if answer.position != len(answers) or answer.position >= len(questions):
                raise UserError(f"answer for question {answer.position + 1} is out of turn")
            doc = answer.to_json()
            doc["time"] = time.strftime("%Y-%m-%dT%H:%M:%S")
            append(self._path(pid), doc)

    def everyone(self) -> list[tuple[str, int, list[Question], list[Answer]]]:
        """(id, number, plan, answers) of every participant, in order of arrival."""
        return [(p["id"], *self.read(p["id"])) for p in self.participants()]
