"""`dfa study new`: make a study's tasks once and freeze them in its folder.

    DIR/protocol.toml          the protocol as given
    DIR/study.json             the protocol, and which frozen task each (slot, shift) is
    DIR/truth.json             per task: its shift, TI or TR, the cause and the concepts a right
                               answer names (read by the analysis only; the page never opens it)
    DIR/tasks/tNN/             failed.npz, demo.npz, counterfactual.npz (when the search found
                               one): sim.core.Trajectory files; saliency.npz (maps float32
                               (T, H, W) in [0, 1]); search.json (the search's result);
                               view.json (what the page may show: what the user wants in
                               words that name nothing R' leaves open, World.intent; the
                               choices; what the counterfactual changed)
    DIR/intro/<world>.npz      the familiarisation's pictures: the concept space, one example of
                               each shift kind, a counterfactual
    DIR/codes.txt              the participant codes issued (dfa_viz.study.codes): the only
                               ones the page accepts

Every task is a pure function of the protocol and the committed base policies: the first
test task of seed protocol.seed + index that the base policy fails (policy.failing_test_task),
the scripted expert's demonstration, the loop's own diagnose step and the page's saliency
overlay. No file holds a pickle; every file is written whole (sim.core.files).
"""

from __future__ import annotations

import io
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dfa_viz.study.codes import DEFAULT_CODES, issue, write_codes
from dfa_viz.study.protocol import Protocol, Slot
from sim.core import Task, Trajectory, UserError, World, files
from sim.core.concepts import PRESENCE

STUDY = "study.json"
TRUTH = "truth.json"
TASKS = "tasks"
INTRO = "intro"


def choices(world: World, task: Task) -> list[dict]:
    """What a participant may name as the cause: every concept the test scene shows, at the
    value it shows ({"key": "goal.colour", "label": "the goal's colour (red)"}; a presence:
    "the distractor in the scene", "that the scene has no lava")."""
    from sim.core.visible import visible_concepts

    out = []
    for uc in visible_concepts(world.space, task.scene):
        kind, concept = uc.name.split(".", 1)
        present = [s for s, c in uc.members if task.scene.obj(s).present]
        if concept == PRESENCE:
            label = f"the {kind} in the scene" if present else f"that the scene has no {kind}"
        else:
            values = dict.fromkeys(task.scene.obj(s).value(concept) for s in present)
            label = f"the {kind}'s {concept} ({', '.join(values)})"
        out.append({"key": uc.name, "label": label})
    return out


def required(world: World, task: Task) -> list[str]:
    """The concepts a right answer must name (the paper's rule): the cause's concept for an
    object shift; for a distractor, every look the added objects show (their colour and shape;
    their presence where they have no looks); none for `other`."""
    if task.cause is None:
        return []
    space = world.space
    slot, concept = task.cause
    if concept != PRESENCE:
        return [space.user_concept(slot, concept).name]
    kind = space.slot(slot).kind
    looks = [
        uc.name
        for uc in space.user_concepts()
        if uc.name.startswith(f"{kind}.")
        and not uc.is_presence
        and any(task.scene.obj(s).present for s, _ in uc.members)
    ]
    return looks or [space.user_concept(slot, PRESENCE).name]


@dataclass(frozen=True)
class Frozen:
    """What `freeze` wrote."""

    folder: Path
    tasks: int
    worlds: tuple[str, ...]
    codes: tuple[str, ...] = ()
    """The participant codes issued, in the order to hand them out."""


def _save_arrays(path: Path, **arrays: np.ndarray) -> None:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    files.write_bytes(path, buf.getvalue())


def _write_json(path: Path, doc) -> None:
    files.write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")


def freeze_task(world: World, policy, slot: Slot, shift: str, protocol: Protocol, folder: Path):
    """Make one task and write its files into `folder`; returns its truth.json entry."""
    from dfa_viz.app.tables import edit_table
    from dfa_viz.loop import diagnose
    from dfa_viz.overlay import failed_saliency
    from dfa_viz.run_record import RunRecord
    from policy import failing_test_task
    from search import SearchConfig

    seed = protocol.seed + slot.index
    task, rollout = failing_test_task(world, policy, shift, seed)
    demo = world.demonstrate(task)
    diagnosis = diagnose(world, policy, task, demo, config=SearchConfig.for_world(world))
    record = RunRecord(world.name, shift, seed, task, rollout, failed=True, demo=demo)
    layer = failed_saliency(world, policy, record, protocol.saliency)
    folder.mkdir(parents=True, exist_ok=True)
    rollout.save(folder / "failed.npz")
    demo.save(folder / "demo.npz")
    if diagnosis.counterfactual is not None:
        diagnosis.counterfactual.save(folder / "counterfactual.npz")
    _save_arrays(folder / "saliency.npz", maps=layer.maps)
    _write_json(folder / "search.json", diagnosis.result.to_json())
    edit = diagnosis.edit
    _write_json(
        folder / "view.json",
        {
            "world": world.name,
            "instruction": world.intent(task),  # not R's words: they name what may change
            "choices": choices(world, task),
            "changed": edit_table(world, task.scene, edit) if edit is not None else None,
        },
    )
    relevance = None if task.cause is None else ("TR" if shift.endswith("_tr") else "TI")
    cause = None if task.cause is None else world.space.user_concept(*task.cause).name
    return {
        "slot": slot.key,
        "shift": shift,
        "kind": slot.kind,
        "relevance": relevance,
        "cause": cause,
        "required": required(world, task),
        "task_seed": task.seed,
        "counterfactual": edit.to_list() if edit is not None else None,
    }


def freeze(
    protocol: Protocol,
    out: Path,
    *,
    protocol_text: str | None = None,
    progress=None,
    participants: int = DEFAULT_CODES,
):
    """Make every task of `protocol`, the familiarisation's pictures and `participants`
    participant codes in `out` (a new or empty folder); returns Frozen. The folder is written
    in a temporary sibling and moved into place once complete, so a study folder is never
    half made."""
    from dfa_viz.study.intro import intro_pictures
    from policy import base_policy
    from sim import get_world

    protocol.check()
    codes = issue(participants)
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"{out}: already exists and is not an empty folder; choose a new --out")
    work = out.with_name(f".{out.name}.making")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    try:
        truth, index, n = {}, {}, 0
        for name, _ in protocol.tasks:
            world = get_world(name)
            policy = base_policy(world)
            for slot in (s for s in protocol.slots if s.world == name):
                for shift in slot.shifts():
                    n += 1
                    tid = f"t{n:02d}"
                    if progress:
                        progress(f"{slot.key} ({shift}) -> {TASKS}/{tid}")
                    truth[tid] = freeze_task(
                        world, policy, slot, shift, protocol, work / TASKS / tid
                    )
                    index.setdefault(slot.key, {})[shift] = tid
            pics = intro_pictures(world, policy, protocol)
            _save_arrays(work / INTRO / f"{files.safe_name(name)}.npz", **pics)
        _write_json(work / TRUTH, truth)
        _write_json(work / STUDY, {"version": 1, "protocol": protocol.to_dict(), "tasks": index})
        text = protocol_text if protocol_text is not None else _toml(protocol)
        files.write_text(work / "protocol.toml", text)
        write_codes(work, codes)
        if out.exists():
            out.rmdir()
        work.rename(out)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    return Frozen(out, n, tuple(w for w, _ in protocol.tasks), tuple(codes))


def _toml(protocol: Protocol) -> str:
    d = protocol.to_dict()
    lines = [
        f"seed = {d['seed']}",
        f'design = "{d["design"]}"',
        "conditions = [" + ", ".join(f'"{c}"' for c in d["conditions"]) + "]",
        "kinds = [" + ", ".join(f'"{k}"' for k in d["kinds"]) + "]",
        f'saliency = "{d["saliency"]}"',
        "",
        "[tasks]",
        *(f'"{w}" = {n}' for w, n in d["tasks"].items()),
    ]
    return "\n".join(lines) + "\n"


# -- reading a frozen study -----------------------------------------------------------------------
def read_json(path: Path):
    try:
        return json.loads(Path(path).read_text())
    except OSError as e:
        raise UserError(
            f"{path}: cannot read it ({e.strerror}); is it a `dfa study new` folder?"
        ) from None
    except (ValueError, RecursionError) as e:
        raise UserError(f"{path}: not a JSON file ({e})") from None


def load_study(folder: Path) -> tuple[Protocol, dict[str, dict[str, str]]]:
    """The protocol and the task index {slot key: {shift: task id}} of a study folder."""
    doc = read_json(Path(folder) / STUDY)
    try:
        return Protocol.from_dict(doc["protocol"], str(Path(folder) / STUDY)), doc["tasks"]
    except (KeyError, TypeError):
        raise UserError(f"{Path(folder) / STUDY}: not a study description") from None


@dataclass(frozen=True, eq=False)
class FrozenTask:
    """One frozen task as the page shows it (no ground truth)."""

    id: str
    world: str
    instruction: str
    choices: tuple[dict, ...]
    changed: str | None
    failed: Trajectory
    counterfactual: Trajectory | None
    saliency: np.ndarray  # (T, H, W) float32 in [0, 1]


def load_task(folder: Path, tid: str) -> FrozenTask:
    path = Path(folder) / TASKS / tid
    view = read_json(path / "view.json")
    cf = path / "counterfactual.npz"
    with np.load(path / "saliency.npz", allow_pickle=False) as z:
        maps = z["maps"]
    return FrozenTask(
        tid,
        view["world"],
        view["instruction"],
        tuple(view["choices"]),
        view["changed"],
        Trajectory.load(path / "failed.npz"),
        Trajectory.load(cf) if cf.exists() else None,
        maps,
    )


def load_intro(folder: Path, world: str) -> dict[str, np.ndarray]:
    path = Path(folder) / INTRO / f"{files.safe_name(world)}.npz"
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except OSError as e:
        raise UserError(f"{path}: cannot read the familiarisation pictures ({e})") from None
