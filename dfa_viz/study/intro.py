"""The familiarisation's pictures of one world: its concepts shown, one example of each shift
kind, and a counterfactual. Each a uint8 (H, W, 3) image, made once by `dfa study new`, beside
the world's words:

    description         a 0-d str array: what the robot is and should do (`world_text`)
    looks               a 0-d str array: the looks a thing can have ("colour or shape";
                        DoorKey: "colour"), said by the introduction of an object change

    concepts            a row per concept: the training scene with each of its values
                        (at most VALUES_SHOWN of them; the tabletop has 29 shapes, 81 colours)
    example_<kind>      the scene the robot learnt on beside a new scene of that kind
    counterfactual      what the robot did, what it was shown, what it does once one thing
                        in the scene is changed (the last frame of each)

The examples use test-task seeds far from the study's own (EXAMPLE_SEED + protocol seed), so
the familiarisation never shows a task that is asked about.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from dfa_viz.app.frames import BACKGROUND, INK, strip
from dfa_viz.fonts import font
from dfa_viz.study.protocol import Protocol
from sim.core import Change, Edit, World
from sim.core.concepts import ABSENT, PRESENCE, PRESENT

VALUES_SHOWN = 8
EXAMPLE_SEED = 10_000
COLOURS = ((120, 124, 130), (28, 126, 214), (230, 119, 0), (47, 158, 68))
_TITLE = font(16)


def titled(title: str, image: np.ndarray) -> np.ndarray:
    """`image` uint8 (H, W, 3) under a line of text: uint8 (H + 28, W', 3)."""
    w = max(
        image.shape[1], int(ImageDraw.Draw(Image.new("RGB", (1, 1))).textlength(title, _TITLE)) + 12
    )
    band = Image.new("RGB", (w, 28), BACKGROUND)
    ImageDraw.Draw(band).text((4, 5), title, fill=INK, font=_TITLE)
    return stack([np.asarray(band), image])


def stack(images: list[np.ndarray], gap_px: int = 8) -> np.ndarray:
    """Images one above the other, left-aligned on the page's background: uint8 (H, W, 3)."""
    w = max(im.shape[1] for im in images)
    parts = []
    for i, im in enumerate(images):
        pad = np.full((im.shape[0], w - im.shape[1], 3), BACKGROUND, np.uint8)
        if i:
            parts.append(np.full((gap_px, w, 3), BACKGROUND, np.uint8))
        parts.append(np.concatenate([im, pad], axis=1))
    return np.ascontiguousarray(np.concatenate(parts, axis=0))


def concept_rows(world: World, scene, extra) -> np.ndarray:
    """The concept space shown: per look concept of each kind, `scene` with each value (the
    scene `extra`, a distractor's, for an object `scene` does not have)."""
    rows, seen = [], set()
    for slot in world.space.slots:
        if slot.kind in seen:
            continue
        seen.add(slot.kind)
        base = scene
        if slot.optional and not scene.obj(slot.name).present:
            base = extra
        if slot.optional and not base.obj(slot.name).present:
            base = world.apply(scene, Edit.of(Change(slot.name, PRESENCE, ABSENT, PRESENT)))
        for concept in slot.concepts:
            now = base.obj(slot.name).value(concept.name)
            values = [now, *[v for v in concept.values if v != now]][:VALUES_SHOWN]
            scenes = [
                base
                if v == now
                else world.apply(base, Edit.of(Change(slot.name, concept.name, now, v)))
                for v in values
            ]
            pics = world.render_batch(scenes)  # (V, H, W, 3) uint8
            cols = [(v, pics[i], "", COLOURS[0]) for i, v in enumerate(values)]
            more = len(concept.values) - len(values)
            title = f"the {slot.kind}'s {concept.name}" + (
                f" (and {more} more)" if more > 0 else ""
            )
            rows.append(titled(title, strip(cols, frame_shape=world.obs_shape)))
    return stack(rows, gap_px=14)


def looks_text(world: World) -> str:
    """The looks the world's things can have, in words: "colour or shape" (nav2d), "colour"
    (DoorKey): every concept but presence, each once, in the order the space names them."""
    names = dict.fromkeys(
        c.name for slot in world.space.slots for c in slot.concepts if c.name != PRESENCE
    )
    return " or ".join(names)


def world_text(world: World, seed: int = EXAMPLE_SEED) -> str:
    """What the familiarisation says of `world`: its description, else what a training task
    asks for."""
    if world.description:
        return world.description
    return f"The robot should do what it is asked: {world.train_task(seed).reward.instruction}."


def intro_pictures(world: World, policy, protocol: Protocol) -> dict[str, np.ndarray]:
    """Every picture of the familiarisation of `world` (see the module's docstring)."""
    from dfa_viz.loop import diagnose
    from policy import failing_test_task
    from search import SearchConfig

    seed = EXAMPLE_SEED + protocol.seed
    train = world.train_task(seed)
    extra = world.test_task("distractor_ti", seed).scene
    out = {
        "description": np.array(world_text(world, seed)),
        "looks": np.array(looks_text(world)),
        "concepts": concept_rows(world, train.scene, extra),
    }
    shape = world.obs_shape
    for kind in protocol.kinds:
        shift = "other" if kind == "other" else f"{kind}_ti"
        test = world.test_task(shift, seed)
        pics = world.render_batch([train.scene, test.scene])
        cols = [
            ("what the robot learnt on", pics[0], "", COLOURS[0]),
            ("a new scene", pics[1], "", COLOURS[2]),
        ]
        out[f"example_{kind}"] = strip(cols, frame_shape=shape)
    task, rollout = failing_test_task(world, policy, "object_ti", seed)
    demo = world.demonstrate(task)
    cf = diagnose(world, policy, task, demo, config=SearchConfig.for_world(world)).counterfactual
    cols = [
        ("what the robot did", rollout.observations[-1], "", COLOURS[2]),
        ("what you showed it", demo.observations[-1], "", COLOURS[3]),
        (
            "after one change",
            None if cf is None else cf.observations[-1],
            "no change found",
            COLOURS[1],
        ),
    ]
    out["counterfactual"] = strip(cols, frame_shape=shape)
    return out
