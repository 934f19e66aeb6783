"""`dfa study analyse`'s scoring and statistics: answers scored by the cause they name, the
exact test by task, the mixed model, and the provenance of answers given on the page."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from dfa_viz.study.codes import CODES
from dfa_viz.study.report import write_analysis

DISTRACTOR = {
    "kind": "distractor",
    "cause": "distractor.presence",
    "required": ["distractor.colour", "distractor.shape"],
}
OBJECT = {"kind": "object", "cause": "goal.colour", "required": ["goal.colour"]}
OTHER = {"kind": "other", "cause": None, "required": []}


@pytest.mark.parametrize(
    ("truth", "selected", "none", "correct", "exact", "precision"),
    [
        (DISTRACTOR, ["distractor.presence"], False, 1, 1, 1.0),  # the planted cause itself
        (DISTRACTOR, ["distractor.colour", "distractor.shape"], False, 1, 1, 1.0),  # its looks
        (DISTRACTOR, ["distractor.colour"], False, 1, 0, 1.0),  # its object, one look
        (DISTRACTOR, ["goal.colour"], False, 0, 0, 0.0),
        (OBJECT, ["goal.colour"], False, 1, 1, 1.0),
        (OBJECT, ["goal.shape"], False, 0, 0, 0.0),  # the object, not the changed concept
        (OBJECT, ["goal.colour", "goal.shape", "wall.colour", "distractor.presence"], False,
         1, 0, 0.25),  # ticking everything includes the cause but is not knowing it
        (OTHER, [], True, 1, 1, None),
        (OTHER, ["goal.colour"], True, 1, 0, None),
        (OBJECT, [], True, 0, 0, None),
    ],
)  # fmt: skip
def test_answers_are_scored_by_the_cause_they_name(truth, selected, none, correct, exact,
                                                   precision, study_check):  # fmt: skip
    """A distractor is named by its presence (the planted cause) or its object; exact match
    and precision stand beside the paper's rule, so that ticking everything scores low."""
    from dfa_viz.study.analysis import is_correct, is_exact
    from dfa_viz.study.analysis import precision as share

    assert is_correct(truth, selected, none) == bool(correct)
    assert study_check.correct(truth, selected, none) == bool(correct)
    assert is_exact(truth, selected, none) == bool(exact)
    got = share(truth, selected, none)
    assert math.isnan(got) if precision is None else got == precision


def _answers(spec):
    """answers.csv-like rows from (participant, task, condition, correct) tuples."""
    return [{"participant": p, "task": t, "condition": c, "correct": int(k)} for p, t, c, k in spec]


def test_the_exact_test_by_task_is_fishers_in_one_task_and_convolves_tasks(study_check):
    from dfa_viz.study.models import stratified_exact

    conds = ("none", "counterfactual")
    # one task: the exact conditional test is Fisher's exact test of its 2 x 2 table
    one = _answers(
        [(f"P{i}", "t1", "counterfactual", i < 4) for i in range(5)]
        + [(f"Q{i}", "t1", "none", i < 1) for i in range(5)]
    )
    (s,) = stratified_exact(one, conds)
    assert (s.strata, s.right, s.expected) == (1, 4, 2.5)
    assert math.isclose(s.p, study_check.fisher(4, 1, 1, 4))
    # two tasks, each one right answer under the counterfactual and one wrong without: each
    # task's count is 0 or 1 with probability 1/2, their sum 0, 1, 2 with 1/4, 1/2, 1/4; the
    # two-sided p of 2 is 1/4 + 1/4
    two = _answers(
        [
            ("A", "t1", "counterfactual", 1),
            ("B", "t1", "none", 0),
            ("A", "t2", "none", 0),
            ("B", "t2", "counterfactual", 1),
        ]
    )
    (s,) = stratified_exact(two, conds)
    assert (s.strata, s.right, s.expected) == (2, 2, 1.0) and math.isclose(s.p, 0.5)
    # a task seen under one condition only says nothing
    (s,) = stratified_exact(_answers([("A", "t1", "none", 1), ("B", "t1", "none", 0)]), conds)
    assert s.strata == 0 and math.isnan(s.p)


def test_the_mixed_model_finds_a_planted_effect_and_not_one_that_is_not_there():
    from dfa_viz.study.models import mixed_model

    rng = np.random.default_rng(0)
    conds = ("none", "counterfactual")
    planted, null = [], []
    for p in range(16):
        skill = rng.normal(0.0, 0.7)
        for t in range(12):
            c = conds[(p + t) % 2]  # within: each participant under both conditions
            for rows, effect in ((planted, 2.5), (null, 0.0)):
                logit = -1.0 + effect * (c == "counterfactual") + skill
                rows.append((f"P{p}", f"t{t}", c, rng.random() < 1 / (1 + math.exp(-logit))))
    (found,) = mixed_model(_answers(planted), conds).effects
    assert found.low > 0.5 and found.p_positive > 0.999
    assert found.low < 2.5 < found.high + 1.0  # near the planted log-odds
    (none,) = mixed_model(_answers(null), conds).effects
    assert none.low < 0 < none.high
    fit = mixed_model(_answers(planted[:5]), conds)
    assert fit.effects == () and "two participants" in fit.note


def _folder(wire, prefix: str) -> str:
    """The label of a shown folder that starts with `prefix` ("" when there is none)."""
    return next(
        (
            g["label"]
            for u, g in list(wire.gui.items())
            if g["type"] == "GuiFolderMessage"
            and str(g.get("label", "")).startswith(prefix)
            and wire.shown(u)
        ),
        "",
    )


def test_answers_given_on_the_page_say_so_and_their_times_are_plotted(study, tmp_path):
    """The real study server and page (viser's protocol, as a browser tab speaks it)."""
    import shutil

    from page_wire import PageWire, free_port
    from PIL import Image

    from dfa_viz.study.page import ASK_MATTERS, MATTERS, NONE_LABEL
    from dfa_viz.study.server import start_study

    folder = tmp_path / "s"
    shutil.copytree(study, folder, ignore=shutil.ignore_patterns("answers", "analysis"))
    (folder / "participants.jsonl").unlink(missing_ok=True)
    code = (folder / CODES).read_text().split()[0]
    app = start_study(folder, port=free_port())
    sessions = []
    try:
        for questions in ((0, 1), (2,)):  # a second tab resumes the code
            wire = PageWire(app.url)
            try:
                wire.wait(lambda w=wire: w.find("Participant code", "Text"), "the code field")
                if not sessions:  # a code not issued: one line, and nobody is numbered
                    wire.update(wire.one("Participant code", "Text"), value="P01")
                    wire.click("Start")
                    wire.wait(lambda w=wire: w.notes, "the refusal")
                    assert wire.notes == [
                        "Not yet: P01 is not a code of this study; type the code you were given"
                    ]
                    assert not (folder / "participants.jsonl").exists()
                typed = f" {code.lower()} " if sessions else code  # as typed: any case, spaces
                wire.update(wire.one("Participant code", "Text"), value=typed)
                wire.click("Start")
                first = f"Question {questions[0] + 1} of 3"
                step = 1
                while True:  # the introduction, one screen at a time, until the question
                    wire.wait(
                        lambda w=wire, q=first, i=step: (
                            _folder(w, q) or _folder(w, f"Introduction {i} of")
                        ),
                        "the introduction or a question",
                    )
                    if _folder(wire, first):
                        break
                    title = _folder(wire, f"Introduction {step} of")
                    last = title.split(" of ")[1].startswith(f"{step}:")
                    wire.click("Start the questions (Enter)" if last else "Next (Enter)")
                    step += 1
                for j in questions:
                    wire.wait(
                        lambda w=wire, j=j: _folder(w, f"Question {j + 1} of 3"), "a question"
                    )
                    wire.update(wire.one(NONE_LABEL, "Checkbox"), value=True)
                    if j == 1:  # after "not among these", "should that matter?" is not asked
                        wire.wait(
                            lambda w=wire: w.gui[w.one(ASK_MATTERS)].get("disabled"),
                            "no matters question",
                        )
                    else:
                        wire.update(wire.one(ASK_MATTERS, "Dropdown"), value=MATTERS[2])
                    wire.click("Submit answer (Enter)")
                    nxt = f"Question {j + 2} of 3" if j < 2 else None
                    wire.wait(
                        lambda w=wire, nxt=nxt: _folder(w, nxt) if nxt else "Thank you" in w.text(),
                        "the next screen",
                    )
            finally:
                wire.close()
            lines = (folder / "answers" / f"{code}.jsonl").read_text().splitlines()
            sessions.append(json.loads(lines[-1])["session"])
    finally:
        app.stop()
    answers = [
        json.loads(x) for x in (folder / "answers" / f"{code}.jsonl").read_text().splitlines()
    ]
    given = [a for a in answers if a.get("type") == "answer"]
    assert len(given) == 3 and all(a["via"] == "page" for a in given)
    assert [a["none"] for a in given] == [True] * 3 and not any(a["matters"] for a in given)
    assert all(a["duration_s"] > 0 for a in given)
    assert [a["session"] for a in given] == [sessions[0], sessions[0], sessions[1]]
    assert sessions[0] != sessions[1] and all(len(s) == 12 for s in sessions)
    a = write_analysis(folder)
    assert [r["via"] for r in a.rows] == ["page"] * 3
    md = (folder / "analysis" / "accuracy.md").read_text()
    assert "3 of 3 answers came through the study page, in 2 page session(s)" in md
    with Image.open(folder / "analysis" / "durations.png") as im:
        pixels = np.asarray(im.convert("RGB"))
    assert pixels.shape[1] > 300 and pixels.std() > 10, "the durations plot is not blank"
