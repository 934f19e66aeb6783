"""Demonstrating in the page, one small class per kind of input a world declares
(World.demo_input):

- "waypoints": click waypoints on the image; the agent follows the path at constant speed.
- "keys": keys or buttons (World.keys), one step each.
- "pick_place": click the pick point, then the place point.
- "effector": click waypoints of a robot's end effector on its frames (the object to grasp it,
  points on the table, a point in the air clicked in two views); the world leads it through.
- "file" (or any world without one of these): only the scripted expert, where there is one.

Every input shows a canvas (the task's top-down image, upscaled, with what the user did drawn
on it) and turns the user's clicks or keys into a Trajectory from the task's initial scene.
Canvas clicks arrive as (u, v) in [0, 1]: u to the right, v down the image; the world's
`image_extent` maps them to its coordinates.
"""

from __future__ import annotations

import numpy as np

from dfa_viz.app import frames
from sim.core import Key, Task, Trajectory, UserError, Waypoint, World

NEAR_SHARE = 0.08  # a click within this share of the image's width is on an object


class DemoInput:
    """The demonstration being built for one task (shared by every tab of a session)."""

    kind = "expert"  # "clicks", "keys" or "expert" (only the scripted expert)
    hint = "Ask the expert for a demonstration."
    keys: tuple[Key, ...] = ()

    def __init__(self, world: World, task: Task) -> None:
        self.world, self.task = world, task
        self.first = world.render(task.scene)  # (H, W, 3) uint8
        self.scale = frames.scale_for(world.obs_shape, frames.CANVAS_PX)
        self._built: tuple[tuple, Trajectory] | None = None  # (what was given, its trajectory)

    def click(self, u: float, v: float) -> None:
        raise UserError(f"{self.world.name} demonstrations are not given by clicking")

    def act(self, action: int) -> None:
        raise UserError(f"{self.world.name} demonstrations are not given with keys")

    def undo(self) -> None: ...

    def clear(self) -> None: ...

    def given(self) -> bool:
        """True once the user has demonstrated something (a click, a key)."""
        return False

    def ready(self) -> bool:
        """True when the demonstration so far does what the task asks (only then may the
        search use it)."""
        return self.given() and self.trajectory().success

    def problem(self) -> str:
        """Why the demonstration cannot be used yet, in words ("" when it can, or before
        anything was given)."""
        if not self.given() or self.ready():
            return ""
        return (
            f'This does not do what the task asks yet ("{self.task.reward.instruction}"); '
            "adjust it, or ask the expert."
        )

    def summary(self) -> str:
        return ""

    def trajectory(self) -> Trajectory:
        """The demonstration given so far, stepped through the world (built once for each
        state of what was given)."""
        key = self._given_key()
        if self._built is None or self._built[0] != key:
            self._built = (key, self._make())
        return self._built[1]

    def _given_key(self) -> tuple:
        """A value that changes whenever what the user gave changes."""
        return ()

    def _make(self) -> Trajectory:
        raise UserError("nothing demonstrated yet")

    def canvas(self) -> np.ndarray:
        """uint8 (H', W', 3): the image to click on, with the demonstration so far."""
        return frames.upscale(self.first, self.scale)

    def _rollout(self, actions: list[np.ndarray]) -> Trajectory:
        return self.world.replay(self.task, np.stack(actions))

    def _to_world(self, u: float, v: float) -> tuple[float, float]:
        """A canvas click (u, v) in [0, 1] as world (x, y), clipped to the image."""
        x0, x1, y0, y1 = self.world.image_extent
        u, v = float(np.clip(u, 0, 1)), float(np.clip(v, 0, 1))
        return x0 + (x1 - x0) * u, y1 - (y1 - y0) * v

    def _to_canvas(self, x: float, y: float) -> tuple[float, float]:
        x0, x1, y0, y1 = self.world.image_extent
        return (x - x0) / (x1 - x0), (y1 - y) / (y1 - y0)

    def _where(self, x: float, y: float) -> str:
        """What a point of the image is on, in words: "on the goal", "on empty floor"."""
        x0, x1, _, _ = self.world.image_extent
        near = NEAR_SHARE * abs(x1 - x0)
        best, slot = near, None
        for o in self.task.scene.objects:
            if o.present and len(o.pos) >= 2:
                d = float(np.hypot(o.pos[0] - x, o.pos[1] - y))
                if d < best:
                    best, slot = d, o.slot
        return f"on the {slot}" if slot is not None else "on empty space"


class WaypointDemo(DemoInput):
    """ "waypoints": the agent walks the clicked path from its start at constant speed."""

    kind = "clicks"
    hint = (
        "Click waypoints on the image in the 3D view (the last one is where the agent should "
        "end); the agent walks the path at constant speed over the episode."
    )

    def __init__(self, world: World, task: Task) -> None:
        super().__init__(world, task)
        self.points: list[tuple[float, float]] = []  # world (x, y)

    def click(self, u: float, v: float) -> None:
        x, y = self._to_world(u, v)
        self.points.append((round(x, 3), round(y, 3)))

    def undo(self) -> None:
        if self.points:
            self.points.pop()

    def clear(self) -> None:
        self.points.clear()

    def given(self) -> bool:
        return bool(self.points)

    def _given_key(self) -> tuple:
        return tuple(self.points)

    def summary(self) -> str:
        if not self.points:
            return ""
        n = len(self.points)
        return f"{n} waypoint{'s' if n > 1 else ''}, ends {self._where(*self.points[-1])}"

    def _make(self) -> Trajectory:
        if not self.points:
            raise UserError("click at least one waypoint first")
        start = np.array(self.task.scene.agent[:2])
        path = np.array([start, *self.points])  # (K+1, 2)
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)  # (K,)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        horizon = self.world.horizon
        targets = np.stack(
            [
                np.interp(cum[-1] * np.arange(1, horizon + 1) / horizon, cum, path[:, k])
                for k in (0, 1)
            ],
            axis=1,
        )  # (T, 2) where the agent should be after each step
        scenes, actions = [self.task.scene], []
        for t in range(horizon):
            a = np.clip(targets[t] - np.array(scenes[-1].agent[:2]), -1, 1).astype(np.float32)
            actions.append(a)
            scenes.append(self.world.step_batch([scenes[-1]], a[None])[0])
        return self._rollout(actions)

    def canvas(self) -> np.ndarray:
        image = super().canvas()
        uv = [self._to_canvas(x, y) for x, y in self.points]
        start = self._to_canvas(*self.task.scene.agent[:2])
        return frames.mark_points(image, uv, start_uv=start, colours=((255, 140, 0),))


ARROWS = {"arrowleft": "←", "arrowright": "→", "arrowup": "↑", "arrowdown": "↓"}


class KeyDemo(DemoInput):
    """ "keys": one step per key press or button; the world's idle action fills the rest."""

    kind = "keys"

    def __init__(self, world: World, task: Task) -> None:
        super().__init__(world, task)
        self.fill = world.idle_action
        self.keys = world.keys
        names = ", ".join(f"{ARROWS.get(k.hotkey, k.hotkey)} {k.label}" for k in world.keys)
        self.hint = (
            f"Drive the agent: {names} (or the buttons). Steps left after the end are filled "
            "by the idle action."
        )
        self.actions: list[int] = []
        self.scenes = [task.scene]

    def act(self, action: int) -> None:
        if not 0 <= action < self.world.action_dim:
            raise UserError(f"action {action} is not one of 0..{self.world.action_dim - 1}")
        if len(self.actions) >= self.world.horizon or self.world.done(self.scenes[-1]):
            return  # the episode is over; further keys do nothing
        self.actions.append(int(action))
        self.scenes.append(self.world.step_batch([self.scenes[-1]], np.array([action]))[0])

    def undo(self) -> None:
        if self.actions:
            self.actions.pop()
            self.scenes.pop()

    def clear(self) -> None:
        self.actions.clear()
        del self.scenes[1:]

    def given(self) -> bool:
        return bool(self.actions)

    def _given_key(self) -> tuple:
        return tuple(self.actions)

    def summary(self) -> str:
        names = {k.action: k.label for k in self.keys}
        done = " (episode over)" if self.world.done(self.scenes[-1]) else ""
        return (
            f"{len(self.actions)} steps: " + ", ".join(names[a] for a in self.actions[-8:]) + done
        )

    def _make(self) -> Trajectory:
        if not self.actions:
            raise UserError("take at least one step first")
        actions = self.actions + [self.fill] * (self.world.horizon - len(self.actions))
        return self._rollout([np.asarray(a, np.int64) for a in actions])

    def canvas(self) -> np.ndarray:
        return frames.upscale(self.world.render(self.scenes[-1]), self.scale)


class PickPlaceDemo(DemoInput):
    """ "pick_place": the first click is where to pick, the second where to place."""

    kind = "clicks"
    hint = "Click the object to pick, then the place to put it (a third click starts over)."

    def __init__(self, world: World, task: Task) -> None:
        super().__init__(world, task)
        self.points: list[tuple[float, float]] = []  # world (x, y), metres on the table

    def click(self, u: float, v: float) -> None:
        if len(self.points) == 2:
            self.points.clear()
        x, y = self._to_world(u, v)
        self.points.append((round(x, 4), round(y, 4)))

    def undo(self) -> None:
        if self.points:
            self.points.pop()

    def clear(self) -> None:
        self.points.clear()

    def given(self) -> bool:
        return len(self.points) == 2

    def _given_key(self) -> tuple:
        return tuple(self.points)

    def summary(self) -> str:
        names = ("pick", "place")
        return "; ".join(
            f"{n} {self._where(x, y)}" for n, (x, y) in zip(names, self.points, strict=False)
        )

    def _make(self) -> Trajectory:
        if len(self.points) != 2:
            raise UserError("click the pick point and then the place point first")
        (px, py), (qx, qy) = self.points
        return self._rollout([np.array([px, py, qx, qy], np.float32)])

    def canvas(self) -> np.ndarray:
        uv = [self._to_canvas(x, y) for x, y in self.points]
        return frames.mark_points(
            super().canvas(),
            uv,
            colours=((255, 200, 0), (0, 200, 255)),
            labels=("pick", "place"),
        )


class EffectorDemo(DemoInput):
    """ "effector": waypoints of a robot's end effector clicked on its frames
    (World.effector_waypoint); the world leads the end effector through them (World.follow)."""

    kind = "clicks"
    hint = (
        "Click where the gripper should go, in order: the object, to grasp it, then where to "
        "take it (on the table; for a point in the air, click it in the first view, then the "
        "same point in the view beside it)."
    )

    def __init__(self, world: World, task: Task) -> None:
        super().__init__(world, task)
        self.waypoints: list[Waypoint] = []
        self.clicks: list[list[tuple[float, float]]] = []  # (u, v) of the clicks that made each

    def click(self, u: float, v: float) -> None:
        last = self.waypoints[-1] if self.waypoints else None
        w = self.world.effector_waypoint(self.task.scene, u, v, last)
        if w is None:
            raise UserError("that click met nothing: click on the table, the object or the target")
        if w.replaces:
            self.waypoints[-1], self.clicks[-1] = w, [*self.clicks[-1][:1], (u, v)]
        else:
            self.waypoints.append(w)
            self.clicks.append([(u, v)])

    def undo(self) -> None:
        if self.waypoints:
            self.waypoints.pop()
            self.clicks.pop()

    def clear(self) -> None:
        self.waypoints.clear()
        self.clicks.clear()

    def given(self) -> bool:
        return bool(self.waypoints)

    def _given_key(self) -> tuple:
        return tuple(self.waypoints)

    def summary(self) -> str:
        n = len(self.waypoints)
        said = ", then ".join(w.describe() for w in self.waypoints)
        return f"{n} waypoint{'s' if n > 1 else ''}: {said}" if n else ""

    def _make(self) -> Trajectory:
        return self.world.follow(self.task, self.waypoints)

    def canvas(self) -> np.ndarray:
        image = super().canvas()
        labels = [str(i + 1) for i in range(len(self.clicks))]
        image = frames.mark_points(
            image, [c[0] for c in self.clicks], colours=((255, 140, 0),), labels=labels
        )
        placed = [(c[1], label) for c, label in zip(self.clicks, labels, strict=True) if len(c) > 1]
        if placed:  # the second clicks, in the view beside the first
            image = frames.mark_points(
                image,
                [uv for uv, _ in placed],
                colours=((0, 200, 255),),
                labels=[label for _, label in placed],
                line=False,
            )
        return image


INPUTS: dict[str, type[DemoInput]] = {
    "waypoints": WaypointDemo,
    "keys": KeyDemo,
    "pick_place": PickPlaceDemo,
    "effector": EffectorDemo,
}


def input_for(world: World, task: Task) -> DemoInput:
    """The demonstration input the world declares (only the expert for "file" worlds)."""
    kind = world.demo_input
    if kind in ("waypoints", "pick_place") and world.image_extent is None:
        kind = "file"  # a click input needs to know where the image lies in the world
    return INPUTS.get(kind, DemoInput)(world, task)
