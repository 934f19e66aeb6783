"""What a MuJoCo model says about its looks: the slots' geoms and sites, their colours, and the
spare distractor bodies added to a model before it is compiled.

A slot is a body (every visual geom of it and of its children) or a site; its colour is the rgba
those geoms show. Colours are named from one palette (PALETTE); a slot's colour as the model
builds it is read from the model and named by the palette entry it equals, or "as built".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

AS_BUILT = "as built"
PALETTE: dict[str, tuple[float, float, float]] = {
    "dark grey": (0.2, 0.2, 0.2),
    "light grey": (0.93, 0.93, 0.93),
    "red": (1.0, 0.0, 0.0),
    "green": (0.1, 0.7, 0.2),
    "blue": (0.15, 0.3, 0.9),
    "yellow": (0.95, 0.85, 0.1),
    "purple": (0.6, 0.2, 0.7),
    "orange": (1.0, 0.5, 0.05),
}
DISTRACTOR_HALF_M = 0.025  # a distractor is a block of this half size, like Fetch's
DISTRACTOR_MASS_KG = 2.0
PARK_Y_M = -2.0  # where absent distractors wait, on the floor, out of every camera's view


@dataclass(frozen=True)
class SlotLooks:
    """The geoms (or sites) one slot's colour is drawn with, and their rgba as built."""

    geoms: tuple[int, ...]
    sites: tuple[int, ...]
    matids: tuple[int, ...]  # (len(geoms),) each geom's material as built
    rgba: np.ndarray  # (len(geoms) + len(sites), 4) geom_rgba and site_rgba as built
    colour: str  # the palette name of the colour as built (AS_BUILT when none matches)


DRAWN_GROUPS = (0, 1, 2)  # the geom groups MuJoCo draws by default


def _visual(model: mujoco.MjModel, g: int, groups: Sequence[int]) -> bool:
    """A geom that is drawn: in one of the groups drawn and not transparent."""
    rgba = model.mat_rgba[model.geom_matid[g]] if model.geom_matid[g] >= 0 else model.geom_rgba[g]
    return int(model.geom_group[g]) in groups and rgba[3] > 0


def _colour(model: mujoco.MjModel, g: int) -> np.ndarray:
    m = model.geom_matid[g]
    return np.array(model.mat_rgba[m] if m >= 0 else model.geom_rgba[g], float)


def body_geoms(
    model: mujoco.MjModel, body: str, groups: Sequence[int] = DRAWN_GROUPS
) -> tuple[int, ...]:
    """The visual geoms (drawn in `groups`) of `body` and of every body below it."""
    root = model.body(body).id
    under = {root}
    for b in range(model.nbody):
        p = b
        while p > 0 and p not in under:
            p = model.body_parentid[p]
        if p in under:
            under.add(b)
    return tuple(
        g for g in range(model.ngeom) if model.geom_bodyid[g] in under and _visual(model, g, groups)
    )


def palette_name(rgb: Sequence[float]) -> str:
    """The palette's name for `rgb` (within 1/255), else AS_BUILT."""
    for name, ref in PALETTE.items():
        if np.abs(np.subtract(rgb[:3], ref)).max() <= 1 / 255:
            return name
    return AS_BUILT


def slot_looks(
    model: mujoco.MjModel,
    *,
    body: str | None = None,
    site: str | None = None,
    groups: Sequence[int] = DRAWN_GROUPS,
) -> SlotLooks:
    """A slot's geoms (a body's, those drawn in `groups`) or site, read from the compiled
    model."""
    geoms = body_geoms(model, body, groups) if body is not None else ()
    sites = (model.site(site).id,) if site is not None else ()
    shown = [_colour(model, g) for g in geoms] + [np.array(model.site_rgba[s]) for s in sites]
    # a geom's own rgba is kept as built: MuJoCo draws a material's rgba only while the geom's
    # is the default one
    rgba = np.array(
        [np.array(model.geom_rgba[g], float) for g in geoms]
        + [np.array(model.site_rgba[s], float) for s in sites]
    ).reshape(-1, 4)
    first = shown[0] if shown else np.ones(4)
    return SlotLooks(
        geoms, sites, tuple(int(model.geom_matid[g]) for g in geoms), rgba, palette_name(first)
    )


def paint(model: mujoco.MjModel, looks: SlotLooks, colour: str | Sequence[float]) -> None:
    """Show the slot in `colour` (in place): as built, or every geom and site in one palette
    colour or red, green and blue in [0, 1] (materials set aside, so that the colour is the
    rgba's)."""
    if isinstance(colour, str) and colour in (looks.colour, AS_BUILT):
        for i, g in enumerate(looks.geoms):
            model.geom_matid[g] = looks.matids[i]
            model.geom_rgba[g] = looks.rgba[i]
        for j, s in enumerate(looks.sites):
            model.site_rgba[s] = looks.rgba[len(looks.geoms) + j]
        return
    rgba = [*(PALETTE[colour] if isinstance(colour, str) else colour), 1.0]
    for g in looks.geoms:
        model.geom_matid[g] = -1
        model.geom_rgba[g] = rgba
    for s in looks.sites:
        model.site_rgba[s] = rgba


STATISTICS = ("meaninertia", "meanmass", "meansize", "extent", "center")


def add_distractors(spec: mujoco.MjSpec, names: Sequence[str], *, group: int = 0) -> None:
    """Spare blocks, each a free body (one geom, colliding, drawn in geom group `group`),
    parked on the floor out of view until a scene brings one into the workspace.

    The model keeps the statistics the environment's own model has (MuJoCo computes them from
    every body: a far-parked block would change the renderer's scale, `extent`, and the
    solver's), and the solver's scale, meaninertia x nv, stays the environment's own although
    each block adds 6 degrees of freedom: the solver stops where the environment's own stops,
    so a rollout is the environment's to the last bits where it is chaotic (a sliding puck)."""
    own = spec.compile()
    for field in STATISTICS:
        setattr(spec.stat, field, np.array(getattr(own.stat, field)).copy())
    spec.stat.meaninertia = own.stat.meaninertia * max(1, own.nv) / (own.nv + 6 * len(names))
    for k, name in enumerate(names):
        body = spec.worldbody.add_body(name=name, pos=park_pos(k))
        # its inertia given, not left to the compiler (which may read it from some geom
        # groups only: robosuite's from group 0); a solid box's
        body.explicitinertial = True
        body.mass = DISTRACTOR_MASS_KG
        body.inertia = [DISTRACTOR_MASS_KG * 2 * DISTRACTOR_HALF_M**2 / 3] * 3
        body.ipos, body.iquat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]  # at its centre
        body.add_freejoint(name=f"{name}:joint")
        body.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[DISTRACTOR_HALF_M] * 3,
            mass=DISTRACTOR_MASS_KG,
            rgba=[*PALETTE["blue"], 1.0],
            condim=3,
            group=group,
        )


def take_part(model: mujoco.MjModel, looks: SlotLooks, present: bool) -> None:
    """A distractor's body in the physics (colliding, falling) when present; touching nothing
    and held still against gravity while absent (in place)."""
    for g in looks.geoms:
        model.geom_contype[g] = model.geom_conaffinity[g] = int(present)
    if looks.geoms:
        model.body_gravcomp[model.geom_bodyid[looks.geoms[0]]] = 0.0 if present else 1.0


def park_pos(k: int) -> list[float]:
    """Where the k-th distractor waits while absent: over the floor, far to one side."""
    return [1.3, PARK_Y_M - 0.2 * k, DISTRACTOR_HALF_M]
