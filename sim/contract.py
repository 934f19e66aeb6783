"""The contract every world keeps, as plain functions: tests/sim/test_world_contract.py runs
them on every registered world, and `dfa check-world NAME` on one of yours.

Each function takes a World and returns nothing when it holds; it raises AssertionError (or a
UserError the world raised) with a message that says what was expected and what came instead.

    CONTRACTS                        (name, function) for each part of the contract, in order
    check_world(world) -> results    every part run, a Result each (what failed, in one line)
"""

from __future__ import annotations

import typing
from collections.abc import Callable
from dataclasses import dataclass

import gymnasium
import numpy as np
from gymnasium.utils.env_checker import check_env

from sim.core import SHIFTS, Edit, Key, UserError, apply, single_changes
from sim.core.view3d import View3D
from sim.core.world import DemoInput


def expect(condition: bool, message: str) -> None:
    """Raise AssertionError(message) unless `condition` (kept under python -O too)."""
    if not condition:
        raise AssertionError(message)


def scenes_of(world, n: int = 4) -> list:
    """Scenes to check: n sample scenes, and for a Benchmark the first test task of each shift."""
    scenes = [world.sample_scene(seed) for seed in range(n)]
    if world.benchmark:
        scenes += [world.test_task(shift, 0).scene for shift in world.shifts]
    return scenes


def gymnasium_env(world) -> None:
    """make_env() passes gymnasium's check_env, and its reset(seed=0) shows the frame of
    sample_scene(0)."""
    env = world.make_env()
    check_env(env.unwrapped if isinstance(env, gymnasium.Wrapper) else env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    expect(
        obs.shape == world.obs_shape and obs.dtype == np.uint8,
        f"reset gives {obs.dtype} {obs.shape}, expected uint8 {world.obs_shape} (obs_shape)",
    )
    expect(
        np.array_equal(obs, world.render(world.sample_scene(0))),
        "the environment's reset(seed=0) frame differs from render(sample_scene(0))",
    )


def rendering(world) -> None:
    """render_batch is deterministic, of the declared shape, and equals render one by one."""
    scenes = scenes_of(world)
    frames = world.render_batch(scenes)
    want = (len(scenes), *world.obs_shape)
    expect(
        frames.shape == want and frames.dtype == np.uint8,
        f"render_batch gives {frames.dtype} {frames.shape}, expected uint8 {want}",
    )
    expect(
        np.array_equal(frames, world.render_batch(scenes)),
        "render_batch gives other pixels the second time for the same scenes",
    )
    for i, (s, f) in enumerate(zip(scenes, frames, strict=True)):
        expect(
            np.array_equal(world.render(s), f), f"render(scene {i}) differs from its batch frame"
        )
    if world.paints is not None:  # a named value painted by its rgb is that value's render
        concept, rgb = world.paints.concept, world.paints.rgb
        shown = [
            (s, o) for s in scenes for o in s.objects if o.present and concept in dict(o.values)
        ]
        expect(bool(shown), f"paints: no present object of these scenes has a {concept!r}")
        for s, o in shown[:4]:
            other = next(v for v in rgb if v != o.value(concept))
            named = world.render(s.with_obj(o.with_value(concept, other)))
            expect(
                np.array_equal(world.render_painted([s], [{o.slot: rgb[other]}])[0], named),
                f"paints: {o.slot} painted {other}'s rgb is not its {other} render",
            )


def stepping(world) -> None:
    """step_batch is deterministic and stepping a batch equals stepping each scene alone."""
    rng = np.random.default_rng(0)
    scenes = scenes_of(world)
    for t in range(min(world.horizon, 6)):
        if world.discrete:
            actions = rng.integers(world.action_dim, size=len(scenes))
        else:
            actions = rng.uniform(-0.3, 0.3, size=(len(scenes), world.action_dim)).astype(
                np.float32
            )
        batch = world.step_batch(scenes, actions)
        expect(len(batch) == len(scenes), f"step {t}: {len(batch)} scenes from {len(scenes)}")
        expect(batch == world.step_batch(scenes, actions), f"step {t}: a second step differs")
        for i, s in enumerate(scenes):
            alone = world.step_batch([s], actions[i : i + 1])[0]
            expect(alone == batch[i], f"step {t}: scene {i} stepped alone differs from its batch")
        scenes = batch


def round_trips(world) -> None:
    """encode/decode gives the scene back, and each single edit undone gives the scene back."""
    space = world.space
    for i, scene in enumerate(scenes_of(world)):
        expect(space.decode(space.encode(scene), scene) == scene, f"scene {i}: decode(encode)")
        presence, values = single_changes(space, scene)
        for change in (presence + values)[:40]:
            edited = apply(space, scene, Edit.of(change))
            undo = type(change)(change.slot, change.concept, change.new, change.old)
            expect(apply(space, edited, Edit.of(undo)) == scene, f"scene {i}: {change} undone")
            expect(
                space.decode(space.encode(edited), edited) == edited,
                f"scene {i} after {change}: decode(encode)",
            )


def capabilities(world) -> None:
    """The capabilities the tools read are declared consistently."""
    expect(
        world.demo_input in typing.get_args(DemoInput),
        f"demo_input is {world.demo_input!r}; accepted: {', '.join(typing.get_args(DemoInput))}",
    )
    if world.demo_input == "keys":
        expect(world.discrete, "demo_input 'keys' needs discrete actions")
        expect(
            bool(world.keys) and all(isinstance(k, Key) for k in world.keys),
            "demo_input 'keys' needs keys: a tuple of sim.core.Key",
        )
        expect(
            all(0 <= k.action < world.action_dim for k in world.keys),
            f"every key's action must be in 0..{world.action_dim - 1}",
        )
        expect(0 <= world.idle_action < world.action_dim, "idle_action is not an action")
    if world.demo_input in ("waypoints", "pick_place"):
        expect(
            world.image_extent is not None and not world.discrete,
            f"demo_input {world.demo_input!r} needs image_extent and continuous actions",
        )
    if world.demo_input == "effector":
        expect(not world.discrete, "demo_input 'effector' needs continuous actions")
    expect(
        isinstance(world.lossless_frames, bool) and isinstance(world.search_first_only, bool),
        "lossless_frames and search_first_only must be bools",
    )
    expect(world.view3d is None or isinstance(world.view3d, View3D), "view3d: a View3D or None")
    expect(
        world.action_names == () or len(world.action_names) == world.action_dim,
        "action_names: () or one name per continuous action dimension (discrete: per action)",
    )
    expect(set(world.shifts) <= set(SHIFTS), f"shifts {world.shifts} must be among {SHIFTS}")
    if world.scene_parameters:  # a scene's own values are within range and set back alike
        scene = world.sample_scene(0)
        values = world.parameters_of(scene)
        expect(
            len(values) == len(world.scene_parameters)
            and world.parameters_of(world.with_parameters(scene, values)) == values,
            "scene_parameters: parameters_of(with_parameters(scene, parameters_of(scene))) "
            "must read back the scene's own values",
        )
    expect(world.benchmark == bool(world.shifts), "a Benchmark makes shifts; a plain World none")
    names = [s.name for s in world.space.slots]
    expect(len(names) == len(set(names)), f"slot names repeat: {names}")


def finite_success(world) -> None:
    """No rollout with a non-finite number in its states is a success."""
    scene = world.sample_scene(0)
    expect(len(scene.agent) > 0, "scene.agent is empty; it holds the agent's state as numbers")
    task = world.task_for(scene)
    bad = type(scene)(scene.world, scene.objects, (float("nan"), *scene.agent[1:]))
    expect(not world.success(task, [scene, bad]), "a rollout ending in a NaN state succeeded")


def shifts(world) -> None:
    """A Benchmark makes a test task of each shift, the expert solves it, and fresh tasks carry
    its R'."""
    if not world.benchmark:  # a plain world is diagnosed from a user's demonstration
        expect(not world.shifts, "a world that is not a Benchmark declares shifts")
        return
    for shift in world.shifts:
        task = world.test_task(shift, 1)
        expect(task.shift == shift, f"test_task({shift!r}, 1) made a {task.shift!r} task")
        expect(task.world == world.name, f"test_task({shift!r}, 1) is for world {task.world!r}")
        demo = world.demonstrate(task)
        expect(demo.success, f"the expert fails test_task({shift!r}, 1): {task.reward.instruction}")
        fresh = world.fresh_tasks(task, 3, seed=1, layouts="train", shifted=True)
        expect(len(fresh) == 3, f"fresh_tasks(n=3) gave {len(fresh)} for {shift}")
        expect(
            all(t.reward == task.reward for t in fresh), f"fresh {shift} tasks change R' (reward)"
        )


CONTRACTS: tuple[tuple[str, Callable], ...] = (
    ("gymnasium environment", gymnasium_env),
    ("rendering", rendering),
    ("stepping", stepping),
    ("encode/decode and edit round trips", round_trips),
    ("capabilities", capabilities),
    ("no non-finite success", finite_success),
    ("shifts, expert and fresh tasks", shifts),
)


@dataclass(frozen=True)
class Result:
    """One part of the contract on one world: passed, or why not (one line)."""

    name: str
    passed: bool
    message: str = ""


def check_world(world) -> list[Result]:
    """Every part of the contract on `world`; whatever a part raises is its failure, in one
    line (the world's own exceptions too: a failing check never stops the others)."""
    out = []
    for name, check in CONTRACTS:
        try:
            check(world)
        except (AssertionError, UserError) as e:
            out.append(Result(name, False, _line(e) or "assertion failed"))
        except Exception as e:  # the world's own code broke: said, not raised
            out.append(Result(name, False, f"{type(e).__name__}: {_line(e)}"))
        else:
            out.append(Result(name, True))
    return out


def _line(e: BaseException) -> str:
    text = str(e).strip()
    return text.splitlines()[0][:300] if text else ""
