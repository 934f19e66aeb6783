"""`dfa study`: the protocol's balanced plans, the frozen tasks, the answers store, the analysis."""

from __future__ import annotations

import csv
import json
import math
from collections import Counter

import numpy as np
import pytest
import rerun as rr

from dfa_viz.cli import main
from dfa_viz.study.answers import Answer, Store
from dfa_viz.study.codes import CODES
from dfa_viz.study.freeze import TRUTH, freeze, load_study, load_task
from dfa_viz.study.protocol import Protocol, plan
from dfa_viz.study.report import write_analysis
from sim import PAPER_WORLDS, get_world
from sim.core import UserError

SMALL = Protocol(tasks=(("nav2d", 1),), conditions=("none", "counterfactual"), seed=0)


def test_the_papers_protocol_gives_balanced_plans():
    assert Protocol().design == "between", "the paper's study was between subjects"
    p = Protocol(conditions=("none", "counterfactual", "saliency", "both"), design="within")
    n = len(p.slots)
    assert n == 12  # one per kind in nav2d and DoorKey, two in the tabletop
    plans = [plan(p, k) for k in range(2 * n)]
    for block in (plans[:n], plans[n:]):  # every slot at every position once per block
        for j in range(n):
            assert len({q[j].slot for q in block}) == n
    two = [s for s in p.slots if s.kind != "other"]
    for q in plans:  # half TI, half TR within each participant
        shifts = Counter(x.shift[-2:] for x in q if x.slot.kind != "other")
        assert shifts == {"ti": len(two) // 2, "tr": len(two) // 2}
    for a, b in zip(
        plans[0::2], plans[1::2], strict=True
    ):  # each batch of two: every slot TI and TR once
        sa = {x.slot: x.shift for x in a}
        assert all(sa[x.slot] != x.shift for x in b if x.slot.kind != "other")
    seen = Counter((x.slot, x.condition) for q in plans[:4] for x in q)
    assert set(seen.values()) == {1}  # within: every slot under every condition once per 4
    between = Protocol(conditions=("none", "counterfactual"), design="between")
    conds = [{x.condition for x in plan(between, k)} for k in range(4)]
    assert all(len(c) == 1 for c in conds)
    assert Counter(c.pop() for c in conds) == {"none": 2, "counterfactual": 2}
    assert plan(p, 5) == plan(p, 5)  # a participant's plan is a function of the protocol


def test_bad_protocols_are_one_line_errors(tmp_path, capsys):
    bad = {
        'conditions = ["none", "hints"]': "unknown condition 'hints'",
        'design = "mixed"': "design is between or within",
        "[tasks]\nnowhere = 1": "unknown world",
        "[tasks]\nnav2d = 0": "from 1 to 20",
        "colour = 3": "unknown key 'colour'",
        'saliency = "lime"': "unknown saliency method 'lime'; accepted: integrated_gradients, "
        "occlusion, grad_cam, kernel_shap",
        "seed = [": "not a TOML file",
    }
    for text, why in bad.items():
        path = tmp_path / "study.toml"
        path.write_text(text + "\n")
        with pytest.raises(UserError, match=why):
            Protocol.load(path)
    assert main(["study", "new", "--protocol", str(path), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("dfa: error:") and "\n" not in err
    assert not (tmp_path / "x").exists()
    assert main(["study", "analyse", str(tmp_path / "missing")]) == 2


def test_frozen_tasks_are_files_without_pickles_or_ground_truth(study):
    protocol, index = load_study(study)
    assert protocol == SMALL
    truth = json.loads((study / TRUTH).read_text())
    assert len(truth) == 5 and {t["shift"] for t in truth.values()} == {
        "object_ti",
        "object_tr",
        "distractor_ti",
        "distractor_tr",
        "other",
    }
    for tid, t in truth.items():
        folder = study / "tasks" / tid
        for npz in folder.glob("*.npz"):
            with np.load(npz, allow_pickle=False) as z:  # raises on a pickled array
                assert all(z[k].dtype != object for k in z.files)
        view = json.loads((folder / "view.json").read_text())
        assert set(view) == {"world", "instruction", "choices", "changed"}
        assert t["shift"] not in json.dumps(view) and '"cause"' not in json.dumps(view)
        task = load_task(study, tid)
        assert task.saliency.dtype == np.float32 and task.saliency.ndim == 3
        assert task.saliency.min() >= 0.0 and task.saliency.max() <= 1.0
        assert set(t["required"]) <= {c["key"] for c in task.choices}
        assert (task.counterfactual is None) == (t["kind"] == "other")
    assert truth[index["nav2d/distractor/0"]["distractor_ti"]]["required"] == [
        "distractor.colour",
        "distractor.shape",
    ]
    with pytest.raises(UserError, match="already exists"):
        freeze(SMALL, study)  # a study folder is never overwritten


def named_cause(world, task, text: str) -> list[str]:
    """What `text` says of what may change, or of the task's cause: a word that leaves a
    concept open ("whatever", "any", ...), the cause's concept's name or any of its values
    (for a presence: the kind's name and every look it can take), but a value R' fixes for
    another object ("the green goal" beside a changed door colour)."""
    import re

    from sim.core.concepts import PRESENCE

    words = ["any", "whatever", "wherever", "ignore", "matter", "matters"]
    if task.cause is not None:
        slot, concept = task.cause
        space = world.space
        kind = space.slot(slot).kind
        fixed = {
            v[0] for s, c, v in task.reward.allowed if len(v) == 1 and space.slot(s).kind != kind
        }
        if concept == PRESENCE:
            looks = [c for sl in space.slots if sl.kind == kind for c in sl.concepts]
            words += [kind, slot, PRESENCE, "present", "absent"]
            words += [v for c in looks if c.name != PRESENCE for v in c.values if v not in fixed]
            words += [c.name for c in looks if c.name != PRESENCE]
        else:
            values = space.slot(slot).concept(concept).values
            words += [concept, *(v for v in values if v not in fixed)]
    low = text.lower()
    return [w for w in words if re.search(rf"\b{re.escape(w.lower())}\b", low)]


@pytest.mark.parametrize("name", PAPER_WORLDS)
def test_no_question_names_what_may_change_or_its_cause(name, study):
    """The study asks World.intent: what the user wants, naming only what R' fixes. The
    reward's own instruction gives the answer away ("go to the red goal, whatever its shape")."""
    world = get_world(name)
    for shift in ("object_ti", "object_tr", "distractor_ti", "distractor_tr", "other"):
        for seed in range(6):
            task = world.test_task(shift, seed)
            text = world.intent(task)
            assert not named_cause(world, task, text), (shift, seed, text)
    leaks = [
        world.test_task(s, 0) for s in ("object_ti", "distractor_ti", "distractor_tr", "other")
    ]
    assert any(named_cause(world, t, t.reward.instruction) for t in leaks), "a check that bites"
    ti, tr = world.test_task("distractor_ti", 0), world.test_task("distractor_tr", 0)
    assert world.intent(ti) != world.intent(tr), "TI and TR must still read differently"
    if name == "nav2d":  # the frozen study shows exactly these words, on every question
        truth = json.loads((study / TRUTH).read_text())
        for tid, t in truth.items():
            task = world.test_task(t["shift"], t["task_seed"])
            shown = load_task(study, tid).instruction
            assert shown == world.intent(task) and not named_cause(world, task, shown)


def test_codes_are_issued_in_advance_and_only_they_are_accepted(study, tmp_path, capsys):
    import re
    import shutil

    from dfa_viz.study.codes import issue
    from dfa_viz.study.server import Study

    codes = (study / CODES).read_text().split()
    assert len(codes) == 4 and len(set(codes)) == 4
    assert all(re.fullmatch(r"P0[1-4]-[A-Z0-9]{4}", c) for c in codes)
    assert [c[:3] for c in codes] == ["P01", "P02", "P03", "P04"]  # handed out in this order
    many = issue(200)
    assert len({c.split("-")[1] for c in many}) > 150, "the random part is not guessable"
    assert many[0].startswith("P001-")
    folder = tmp_path / "s"
    shutil.copytree(study, folder, ignore=shutil.ignore_patterns("answers", "analysis"))
    (folder / "participants.jsonl").unlink(missing_ok=True)
    s = Study(folder)
    page, other = object(), object()
    for stray in ("P99", "P01", codes[0] + "X", ""):
        with pytest.raises(UserError, match="is not a code of this study"):
            s.claim(stray, page)
    assert s.claim(codes[2].lower(), page) == codes[2]
    with pytest.raises(UserError, match="open in another window"):
        s.claim(codes[2], other)
    assert not (folder / "participants.jsonl").exists(), "no stray code was numbered"
    (folder / CODES).unlink()
    with pytest.raises(UserError, match=r"codes\.txt: missing"):
        Study(folder)
    err = tmp_path / "bad"
    assert main(["study", "new", "--out", str(err), "--participants", "0"]) == 2
    assert "from 1 to 999, not 0" in capsys.readouterr().err and not err.exists()


def test_answers_are_appended_durably_and_resume(tmp_path):
    store = Store(tmp_path, SMALL)
    number, questions, answers = store.join("P01")
    assert (number, answers, len(questions)) == (0, [], 3)
    a = Answer(0, "t01", ("goal.shape",), False, True, 1.5)
    store.answer("P01", a)
    with pytest.raises(UserError, match="out of turn"):
        store.answer("P01", a)
    path = tmp_path / "answers" / "P01.jsonl"
    with open(path, "ab") as f:  # a crash while writing the next answer
        f.write(b'{"type":"answer","posi')
    again = Store(tmp_path, SMALL).join("P01")
    assert again == (0, questions, [a])
    store.answer("P01", Answer(1, "t05", (), True, False, 2.0))  # the torn line is cut off
    assert len(path.read_text().splitlines()) == 3
    assert store.join("P02")[0] == 1
    with pytest.raises(UserError, match="never a name"):
        store.join("Ada Lovelace")


def test_the_analysis_matches_the_statistics_computed_again(study, study_check):
    protocol, index = load_study(study)
    truth = json.loads((study / TRUTH).read_text())
    store = Store(study, protocol)
    # four participants: those under the counterfactual name the cause, the others do not
    for k in range(4):
        pid = f"A{k}"
        _, questions, _ = store.join(pid)
        for j, q in enumerate(questions):
            tid = index[q.slot.key][q.shift]
            t = truth[tid]
            right = q.condition == "counterfactual" or (k == 0 and t["kind"] == "object")
            none = right if t["kind"] == "other" else not right
            sel = () if none else tuple(t["required"]) if right else ("goal.colour",)
            store.answer(pid, Answer(j, tid, sel, none, t["relevance"] == "TR", 1.0 + j))
    a = write_analysis(study)
    with open(study / "analysis" / "answers.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(a.rows) == 12
    for r in rows:
        t = truth[r["task"]]
        sel = r["selected"].split()
        assert int(r["correct"]) == study_check.correct(t, sel, r["none"] == "1")
    for c in a.cells:
        mine = [
            int(r["correct"])
            for r in rows
            if (r["world"], r["kind"], r["condition"]) == (c.world, c.kind, c.condition)
        ]
        p = sum(mine) / len(mine)
        assert (c.n, c.accuracy) == (len(mine), p)
        assert math.isclose(c.se, math.sqrt(p * (1 - p) / len(mine)))
    (test,) = a.chi2
    cf = [int(r["correct"]) for r in rows if r["condition"] == "counterfactual"]
    no = [int(r["correct"]) for r in rows if r["condition"] == "none"]
    stat, p = study_check.chi2(sum(cf), len(cf) - sum(cf), sum(no), len(no) - sum(no))
    assert math.isclose(test.chi2, stat) and math.isclose(test.p, p)
    exact = study_check.fisher(sum(cf), len(cf) - sum(cf), sum(no), len(no) - sum(no))
    assert math.isclose(test.fisher_p, exact) and test.small  # 12 answers: small cells
    pairs = {}
    for r in rows:
        if r["relevance"]:
            pairs.setdefault(r["participant"], {"TR": [], "TI": []})[r["relevance"]].append(
                int(r["matters"])
            )
    tr = [np.mean(v["TR"]) for v in pairs.values() if v["TR"] and v["TI"]]
    ti = [np.mean(v["TI"]) for v in pairs.values() if v["TR"] and v["TI"]]
    assert a.pairs == len(tr) == 4
    assert math.isclose(a.wilcoxon_p, study_check.wilcoxon(tr, ti))
    assert a.rejection == 1.0
    assert a.design == "between" and {r["via"] for r in rows} == {"direct"}
    # the model keeps each participant's answers together; the exact test is by task
    (effect,) = a.mixed.effects
    assert effect.condition == "counterfactual" and effect.mean > 0 and effect.p_positive > 0.9
    (exact,) = a.exact
    by_task: dict = {}
    for r in rows:
        by_task.setdefault(r["task"], set()).add(r["condition"])
    assert exact.strata == sum(len(c) == 2 for c in by_task.values())
    md = (study / "analysis" / "accuracy.md").read_text()
    assert "97%" in md and "79%" in md  # the paper's numbers beside ours
    assert "0 of 12 answers came through the study page" in md
    assert "## Conditions compared, one participant's answers kept together" in md
    assert (study / "analysis" / "durations.png").read_bytes()[:4] == b"\x89PNG"
    assert (study / "analysis" / "accuracy.png").read_bytes()[:4] == b"\x89PNG"
    logged = set()
    for chunk in rr.chunk.RrdReader(study / "analysis" / "answers.rrd").store().stream():
        logged.add(str(chunk.entity_path))
    assert {"/answers/correct", "/answers/log", "/study/results"} <= logged
    assert main(["study", "analyse", str(study)]) == 0


def test_the_familiarisation_shows_each_explanation_only_to_those_who_get_it(study):
    from dfa_viz.study.freeze import load_intro
    from dfa_viz.study.page import intro_screens

    def pictures(world):
        return load_intro(study, world)

    plain = intro_screens(SMALL, {"none"}, pictures)
    full = intro_screens(SMALL, {"none", "both"}, pictures)
    titles = [t for t, _, _ in full]
    assert [t for t, _, _ in plain] == titles[:5]  # how it works, the looks, 3 kinds of change
    assert titles[5:] == ["After one change (nav2d)", "Where it looked"]
    for _, text, picture in full:
        for jargon in ("R'", "Δφ", "counterfactual", "task-irrelevant", "TI ", "TR "):
            assert jargon not in text
        assert picture is None or (picture.dtype == np.uint8 and picture.shape[2] == 3)
    looks = next(text for title, text, _ in full if title == "The things in the scene (nav2d)")
    assert looks.startswith(get_world("nav2d").description + " These are the looks")
    assert "the colour or shape of something" in full[2][1]  # nav2d's looks


def test_doorkey_is_introduced_by_its_own_looks_and_presence_reads_as_a_cause():
    from dfa_viz.study.freeze import choices
    from dfa_viz.study.intro import looks_text
    from dfa_viz.study.page import intro_screens

    doorkey = get_world("doorkey")
    assert looks_text(doorkey) == "colour" and looks_text(get_world("nav2d")) == "colour or shape"
    shown = {"concepts": None, "description": "", "looks": looks_text(doorkey)}
    shown |= {f"example_{k}": None for k in ("object", "distractor", "other")}
    p = Protocol(tasks=(("doorkey", 1),))
    texts = " ".join(text for _, text, _ in intro_screens(p, {"none"}, lambda w: shown))
    assert "shape" not in texts and "the colour of something it knows" in texts
    labels = {
        c["key"]: c["label"]
        for shift in ("object_ti", "distractor_tr")
        for c in choices(doorkey, doorkey.test_task(shift, 0))
    }
    assert labels["lava.presence"] in ("the lava in the scene", "that the scene has no lava")
    absent = [c["label"] for c in choices(doorkey, doorkey.test_task("object_ti", 0))]
    present = [c["label"] for c in choices(doorkey, doorkey.test_task("distractor_tr", 0))]
    assert "that the scene has no lava" in absent and "the lava in the scene" in present


def test_a_world_without_a_description_is_introduced_by_what_it_is_asked():
    from dfa_viz.study.intro import world_text

    world = get_world("minigrid:MiniGrid-DoorKey-5x5-v0")
    assert world.description == ""
    instruction = world.train_task(0).reward.instruction
    assert instruction and world_text(world, 0).endswith(f"{instruction}.")
    assert world_text(get_world("doorkey")) == get_world("doorkey").description != ""
