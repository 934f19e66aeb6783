"""Any gymnasium environment with image observations and a state that can be saved and restored,
as a world: the user gives the environment id, a state getter and setter, and a table of
concept edits; the rest (concept space, scenes, shifts, fresh tasks) is made here.

    GymWorld(name, env_id=..., get_state=..., set_state=..., concepts=(ConceptEdit(...), ...),
             expert=...)

State     get_state(env) -> numbers (1-D), set_state(env, numbers): everything the environment
          needs to go on from where it was (env is the unwrapped environment). Restoring a
          state and stepping must give what stepping the environment gave.
Concepts  ConceptEdit("slot.concept", values, apply): apply(state, value) -> the state with
          that value. values[0] is what the environment's reset gives (the training look);
          "slot.presence" with values ("absent", "present") in either order makes the slot
          optional (it then needs a look concept too). Concepts keep their values as the
          episode goes on.
Frames    observe(env) -> uint8 (H, W, 3), by default env.render() (render_mode "rgb_array"):
          the same pixels the environment's observation shows in that state.
Scene     agent = (layout, t, won, ended, *state): the reset seed it came from, the step, the
          environment's success so far, the episode's end, and the state with the scene's
          concept values applied as it is restored. Obj.pos = (k,), the slot's index: where an
          object stands is in the state (an added object stands where the state puts it).
Dynamics  the environment's own step, one scene at a time, its np_random seeded from (layout, t)
Success   succeeded(reward, terminated, info), by default a positive reward as it terminates
Shifts    object_ti (one look concept at a value training never showed; R' accepts any),
          distractor_ti (an optional slot training leaves absent, added in any look), each on a
          test layout (reset seeds from 1,000,000 on) that the expert solves. The expert,
          expert(state) -> action, must act as if the shifted concept were not there.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import gymnasium
import numpy as np

from sim.core import (
    ABSENT,
    PRESENCE,
    PRESENT,
    Benchmark,
    Change,
    Concept,
    ConceptSpace,
    Edit,
    Key,
    Obj,
    Reward,
    Scene,
    Slot,
    Task,
    Trajectory,
    UserError,
    carrying_shift,
    check_shift,
    draw_from_reward,
)

HEAD = 4  # agent[:HEAD] = (layout, t, won, ended); the environment's state follows
TEST_LAYOUTS = 1_000_000  # test and fresh tasks reset with seeds from here on
MAX_TRIES = 200
SUCCESS = "env_success"


@dataclass(frozen=True)
class ConceptEdit:
    """One row of the concept table: "slot.concept", its values (values[0]: what reset gives),
    and apply(state, value) -> state, the state (float64 (D,)) with that value."""

    name: str
    values: tuple[str, ...]
    apply: Callable[[np.ndarray, str], np.ndarray]

    @property
    def slot(self) -> str:
        return self.name.partition(".")[0]

    @property
    def concept(self) -> str:
        return self.name.partition(".")[2]


def _space(concepts: Sequence[ConceptEdit], name: str) -> ConceptSpace:
    slots: dict[str, list[ConceptEdit]] = {}
    for c in concepts:
        if c.name.count(".") != 1 or not c.slot or not c.concept or len(c.values) < 1:
            raise UserError(f"{name}: concept {c.name!r} must be 'slot.concept' with values")
        if c.concept == PRESENCE and set(c.values) != {PRESENT, ABSENT}:
            raise UserError(f"{name}: {c.name} takes the values {PRESENT!r} and {ABSENT!r}")
        if len(set(c.values)) != len(c.values):
            raise UserError(f"{name}: {c.name} repeats a value")
        slots.setdefault(c.slot, []).append(c)
    out = []
    for slot, rows in slots.items():
        looks = tuple(Concept(c.concept, tuple(c.values)) for c in rows if c.concept != PRESENCE)
        optional = any(c.concept == PRESENCE for c in rows)
        if optional and not looks:
            raise UserError(f"{name}: the optional slot {slot!r} needs a look concept too")
        out.append(Slot(slot, looks, optional=optional))
    return ConceptSpace(tuple(out))


def _env_success(reward: float, terminated: bool, info: dict) -> bool:
    return bool(terminated and reward > 0)


class GymWorld(Benchmark):
    """A gymnasium environment as a world; see the module docstring.

    Optional keywords: observe (frames), succeeded (success), instruction (R' in words),
    horizon (default: the id's max_episode_steps), epsilon (the search's per-step L1 bound for
    continuous actions), keys (the page's buttons for discrete actions: demonstrations by
    keyboard), make_kwargs (for gymnasium.make; render_mode "rgb_array" by default).
    """

    lossless_frames = True

    def __init__(
        self,
        name: str,
        *,
        env_id: str,
        get_state: Callable[[gymnasium.Env], Sequence[float]],
        set_state: Callable[[gymnasium.Env, np.ndarray], None],
        concepts: Sequence[ConceptEdit],
        expert: Callable[[np.ndarray], int | np.ndarray],
        observe: Callable[[gymnasium.Env], np.ndarray] | None = None,
        succeeded: Callable[[float, bool, dict], bool] = _env_success,
        instruction: str = "do what the environment rewards",
        horizon: int | None = None,
        epsilon: float = 0.1,
        keys: tuple[Key, ...] = (),
        make_kwargs: dict | None = None,
    ) -> None:
        self.name, self.env_id = name, env_id
        self.make_kwargs = {"render_mode": "rgb_array", **(make_kwargs or {})}
        self._get, self._set, self._expert = get_state, set_state, expert
        self._observe = observe or (lambda env: env.render())
        self._succeeded, self.instruction = succeeded, instruction
        self.concepts = tuple(concepts)
        self.space = _space(self.concepts, name)
        self.index = {s.name: float(k) for k, s in enumerate(self.space.slots)}
        self.lock = threading.RLock()
        try:
            self.env = gymnasium.make(env_id, **self.make_kwargs).unwrapped
        except gymnasium.error.Error as e:
            raise UserError(f"{name}: gymnasium cannot make {env_id!r} ({e})") from None
        obs, act = self.env.observation_space, self.env.action_space
        shape = tuple(getattr(obs, "shape", None) or ())
        if len(shape) != 3 or shape[2] != 3 or obs.dtype != np.uint8:
            raise UserError(f"{name}: {env_id} observes {obs}; a world needs uint8 (H, W, 3)")
        self.obs_shape = shape
        self.discrete = isinstance(act, gymnasium.spaces.Discrete)
        if not self.discrete and len(getattr(act, "shape", ())) != 1:
            raise UserError(f"{name}: {env_id} acts in {act}; a world takes Discrete or (A,) Box")
        self.action_dim = int(act.n) if self.discrete else int(act.shape[0])
        spec_steps = getattr(gymnasium.spec(env_id), "max_episode_steps", None)
        self.horizon = int(horizon or spec_steps or 0)
        if self.horizon < 1:
            raise UserError(f"{name}: {env_id} has no max_episode_steps; give horizon=")
        self.keys, self.epsilon = keys, float(epsilon)
        self.demo_input = "keys" if keys and self.discrete else "file"
        self.shifts = tuple(
            s
            for s, offered in (
                ("object_ti", any(len(c.values) > 1 for s in self.space.slots for c in s.concepts)),
                ("distractor_ti", bool(self._addable())),
            )
            if offered
        )

    def _addable(self) -> list[Slot]:
        """The optional slots training leaves absent: what a distractor shift adds."""
        return [
            s for s in self.space.slots if s.optional and self._first(s.name, PRESENCE) == ABSENT
        ]

    # -- scenes and the environment -----------------------------------------------------------
    def _values(self, scene: Scene) -> list[tuple[ConceptEdit, str]]:
        out = []
        for c in self.concepts:
            o = scene.obj(c.slot)
            out.append(
                (
                    c,
                    (PRESENT if o.present else ABSENT)
                    if c.concept == PRESENCE
                    else o.value(c.concept),
                )
            )
        return out

    def state_of(self, scene: Scene) -> np.ndarray:
        """float64 (D,): the scene's state with its concept values applied."""
        state = np.asarray(scene.agent[HEAD:], np.float64)
        for c, value in self._values(scene):
            state = np.asarray(c.apply(state.copy(), value), np.float64)
        return state

    def _restore(self, scene: Scene) -> gymnasium.Env:
        self._set(self.env, self.state_of(scene))
        return self.env

    def _read(self) -> tuple[float, ...]:
        state = np.asarray(self._get(self.env), np.float64).ravel()
        return tuple(float(v) for v in state)

    @functools.lru_cache(maxsize=4096)  # noqa: B019 (one world per name and process)
    def layout_scene(self, layout: int) -> Scene:
        """The environment reset with seed `layout`, its concepts at their training values."""
        with self.lock:
            self.env.reset(seed=int(layout))
            state = self._read()
        objects = []
        for s in self.space.slots:
            present = not s.optional or self._first(s.name, PRESENCE) == PRESENT
            values = tuple((c.name, c.values[0]) for c in s.concepts)
            objects.append(Obj(s.name, present, values, (self.index[s.name],)))
        return Scene(self.name, tuple(objects), (float(layout), 0.0, 0.0, 0.0, *state))

    def _first(self, slot: str, concept: str) -> str:
        return next(c.values[0] for c in self.concepts if c.name == f"{slot}.{concept}")

    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3): observe() of each scene restored."""
        out = np.empty((len(scenes), *self.obs_shape), np.uint8)
        with self.lock:
            for b, scene in enumerate(scenes):
                out[b] = self._observe(self._restore(scene))
        return out

    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        actions = np.asarray(actions)
        want = (len(scenes),) if self.discrete else (len(scenes), self.action_dim)
        assert actions.shape == want, f"actions must be {want}, got {actions.shape}"
        if self.discrete:
            return [self.step_one(s, int(a)) for s, a in zip(scenes, actions, strict=True)]
        return [
            self.step_one(s, tuple(map(float, a))) for s, a in zip(scenes, actions, strict=True)
        ]

    @functools.lru_cache(maxsize=16384)  # noqa: B019 (one world per name and process)
    def step_one(self, scene: Scene, action) -> Scene:
        """The scene after the environment's own step (an ended scene comes back unchanged)."""
        if self.done(scene):
            return scene
        layout, t, won, _ = scene.agent[:HEAD]
        with self.lock:
            env = self._restore(scene)
            env.np_random = np.random.default_rng([int(layout), int(t)])
            a = action if self.discrete else np.asarray(action, np.float32)
            _, reward, terminated, truncated, info = env.step(a)
            won = float(bool(won) or self._succeeded(float(reward), bool(terminated), info))
            ended = float(bool(terminated or truncated) or t + 1 >= self.horizon)
            state = self._read()
        return Scene(scene.world, scene.objects, (layout, t + 1, won, ended, *state))

    def done(self, scene: Scene) -> bool:
        return scene.agent[3] > 0

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        return scenes[-1].agent[2] > 0

    def make_env(self):
        return gymnasium.make(self.env_id, **self.make_kwargs)

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        """An added object stands where the state puts it (its pos is the slot's index)."""
        return [(self.index[slot],)]

    # -- tasks --------------------------------------------------------------------------------
    def _reward(self, open_: Sequence[tuple[str, str]], what: str = "") -> Reward:
        allowed = tuple((s, c, self.space.values(s, c)) for s, c in open_)
        return Reward(f"{self.instruction}{what}", frozenset(), allowed, success=SUCCESS)

    def train_task(self, seed: int = 0) -> Task:
        return Task(self.name, self.layout_scene(seed), self._reward(()), "train", seed)

    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        with self.lock:
            state = self.state_of(scene)
        return np.asarray(self._expert(state), np.int64 if self.discrete else np.float32)

    def _solved(self, task: Task) -> bool:
        return self.demonstrate(task).success

    def test_task(self, shift: str, seed: int) -> Task:
        """A shifted task of kind `shift` (self.shifts), from np.random.default_rng([seed, 2])."""
        check_shift(shift)
        if shift not in self.shifts:
            raise UserError(
                f"{self.name} makes no {shift} tasks; accepted: {', '.join(self.shifts)}"
            )
        rng = np.random.default_rng([seed, 2])
        for _ in range(MAX_TRIES):
            base = self.layout_scene(TEST_LAYOUTS + int(rng.integers(TEST_LAYOUTS)))
            if shift == "object_ti":
                looks = [
                    (s.name, c)
                    for s in self.space.slots
                    if base.obj(s.name).present
                    for c in s.concepts
                    if len(c.values) > 1
                ]
                slot, concept = looks[int(rng.integers(len(looks)))]
                new = concept.values[1 + int(rng.integers(len(concept.values) - 1))]
                old = base.obj(slot).value(concept.name)
                scene = self.apply(base, Edit.of(Change(slot, concept.name, old, new)))
                reward = self._reward(
                    [(slot, concept.name)], f" (whatever the {slot}'s {concept.name})"
                )
                cause = (slot, concept.name)
            else:
                optional = self._addable()
                s = optional[int(rng.integers(len(optional)))]
                open_ = [(s.name, PRESENCE), *((s.name, c.name) for c in s.concepts)]
                reward = self._reward(open_, f" (whatever else is there: the {s.name} too)")
                look = tuple(
                    (c.name, c.values[int(rng.integers(len(c.values)))]) for c in s.concepts
                )
                scene = base.with_obj(Obj(s.name, True, look, base.obj(s.name).pos))
                cause = (s.name, PRESENCE)
            task = Task(self.name, scene, reward, shift, seed, cause)
            if self._solved(task):
                return task
        raise UserError(
            f"{self.name}: no solvable {shift} task in {MAX_TRIES} draws for seed {seed}"
        )

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        """n tasks drawn from the task's R' (carrying its shift when `shifted`): on its own
        layout ("task") or on fresh ones ("train"), each solved by the expert."""
        rng = np.random.default_rng([seed, 3])
        reward = carrying_shift(self.space, task) if shifted else task.reward
        out: list[Task] = []
        for _ in range(MAX_TRIES * n):
            if len(out) == n:
                break
            layout = (
                int(task.scene.agent[0])
                if layouts == "task"
                else TEST_LAYOUTS + int(rng.integers(TEST_LAYOUTS))
            )
            scene = draw_from_reward(self.layout_scene(layout), reward, rng)
            fresh = Task(
                self.name, scene, task.reward, task.shift, seed * 1000 + len(out), task.cause
            )
            if self._solved(fresh):
                out.append(fresh)
        if len(out) < n:
            raise UserError(f"{self.name}: only {len(out)} of {n} fresh tasks were solvable")
        return out
