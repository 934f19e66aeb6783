"""The Sweep tab of one page: sweep the chosen world's policy over its training tasks, read the
heatmap and the ranking, and click a cell of the heatmap (drawn over the 3D view, where the
page takes clicks) to load the failure it stands for as the task to diagnose.

The heatmap lies on its own plane just above the task's image, padded to a square, while
"pick a failure on the heatmap" is on; the canvas ignores clicks then.
"""

from __future__ import annotations

import threading

import numpy as np
import viser

from dfa_viz.app.canvas import SIZE, Canvas, ray
from dfa_viz.app.controls import Checked, whole
from dfa_viz.app.offers import SWEEP_TASKS
from dfa_viz.app.state import LoopState
from sim.core import UserError

DEFAULT_TASKS = 20
PLANE_Z = 0.05  # above the canvas plane (z = 0)
PLANE = 1.4 * SIZE  # the heatmap's side in scene units (the view shows more than the canvas)
PICK = "pick a failure on the heatmap (in the 3D view)"
INTRO = (
    "Every single concept edit (each value of each concept of each object, each object added "
    "or removed) rolled out on training tasks: how much more often the policy then fails what "
    "the task asks than on the same tasks unedited. **Run sweep**, then click a cell of the "
    "heatmap to diagnose that failure."
)


def padded(image: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
    """The image centred on a white square, and its offset (x, y) in pixels."""
    h, w = image.shape[:2]
    side = max(h, w)
    out = np.full((side, side, 3), 255, np.uint8)
    x, y = (side - w) // 2, (side - h) // 2
    out[y : y + h, x : x + w] = image
    return out, (x, y)


class SweepTab:
    def __init__(
        self, client: viser.ClientHandle, state: LoopState, panel, canvas: Canvas, *, world, warn
    ) -> None:
        """panel: the compare panel (the tab goes there); world: the page's chosen world."""
        self.client, self.state, self.canvas = client, state, canvas
        self.world, self.warn = world, warn
        self._lock = threading.Lock()
        self._shown = None
        self.plane: viser.ImageHandle | None = None
        self._plane_of = None
        gui = client.gui
        with panel.add_tab("Sweep", viser.Icon.GRID_DOTS):
            gui.add_markdown(INTRO)
            low, high = SWEEP_TASKS
            tasks = gui.add_number("tasks", DEFAULT_TASKS, min=low, max=high, step=1)
            self.tasks = Checked(tasks, whole(low, high), client)
            self.run = gui.add_button("Run sweep", icon=viser.Icon.PLAYER_PLAY)
            self.run.on_click(self._on_run)
            self.pick = gui.add_checkbox(PICK, False, visible=False)
            self.summary = gui.add_markdown("")
            self.image = gui.add_image(
                np.full((8, 8, 3), 255, np.uint8), label="heatmap", format="png", visible=False
            )
        self.pick.on_update(lambda _: self._show_plane())
        client.scene.on_click()(self._on_click)

    def _on_run(self, _event) -> None:
        try:
            if not self.state.run_sweep(self.world(), self.tasks.value):
                self.warn("a job is running; wait for it to finish")
        except UserError as e:
            self.warn(str(e))

    def refresh(self, busy: bool) -> None:
        """Redraw after a change of the state: a new sweep, or a job starting or ending."""
        self.run.disabled = busy
        shown = self.state.sweep
        with self._lock:
            if shown is self._shown:
                return
            self._shown = shown
        if shown is None:
            return
        self.summary.content = summary_text(shown.result)
        self.image.image = shown.heatmap.image
        self.image.visible = True
        self.pick.visible = True
        self.pick.value = True
        self._show_plane()

    def _show_plane(self) -> None:
        with self._lock:
            self._draw_plane()

    def _draw_plane(self) -> None:
        shown = self._shown
        on = bool(self.pick.value) and shown is not None
        self.canvas.covered = on
        if not on:
            if self.plane is not None:
                self.plane.visible = False
            return
        square, _ = padded(shown.heatmap.image)
        image = np.ascontiguousarray(np.flipud(square))  # viser draws row 0 at -y
        if self._plane_of is shown and self.plane is not None:
            self.plane.visible = True
        elif self.plane is None:
            self.plane = self.client.scene.add_image(
                "/sweep/heatmap",
                image,
                PLANE,
                PLANE,
                format="png",
                position=(0.0, 0.0, PLANE_Z),
                receive_shadow=False,
            )
        else:
            self.plane.image = image
            self.plane.visible = True
        self._plane_of = shown
        self.canvas.pin_camera()

    def _on_click(self, event) -> None:
        shown = self._shown
        o, d = ray(event)
        if shown is None or not self.pick.value or o is None:
            return
        hit = o + (PLANE_Z - o[2]) / d[2] * d  # (3,) on the heatmap's plane
        square, (x0, y0) = padded(shown.heatmap.image)
        side = square.shape[0]
        h, w = shown.heatmap.image.shape[:2]
        px, py = (hit[0] / PLANE + 0.5) * side - x0, (0.5 - hit[1] / PLANE) * side - y0
        key = shown.heatmap.cell_at(px / w, py / h) if 0 <= px < w and 0 <= py < h else None
        if key is None:
            self.warn("that click missed the heatmap's cells")
            return
        try:
            cell = shown.result.cell(*key)
        except KeyError:
            self.warn(f"{key[0]}.{key[1]}={key[2]} changes nothing on these tasks")
            return
        if cell.example is None:
            self.warn(f"{cell.label}: the policy never failed with it")
            return
        try:
            if not self.state.load_failure(shown.world, cell.example):
                self.warn("a job is running; wait for it to finish")
                return
        except UserError as e:
            self.warn(str(e))
            return
        self.pick.value = False
        self._show_plane()


def summary_text(result, shown: int = 5) -> str:
    """The sweep in a few lines: the worst concepts and edits."""
    lines = [
        f"**{result.world}**: {len(result.cells)} single edits on {result.tasks} tasks "
        f"({result.distinct} distinct), {result.rollouts} rollouts. The heatmap shows each "
        "edit's failure rate minus the same tasks' unedited (points).",
        "",
        "| concept | fails | unedited | difference |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {c.slot}.{c.concept} | {c.failure_rate:.0%} of {c.n} | {c.control_rate:.0%} | "
        f"{_points(c)} |"
        for c in result.concepts[:shown]
        if c.n
    ]
    lines += ["", "| edit | fails | unedited | difference |", "|---|---|---|---|"]
    lines += [
        f"| {c.label} | {c.failure_rate:.0%} of {c.n} | {c.control_rate:.0%} | {_points(c)} |"
        for c in result.cells[:shown]
        if c.n
    ]
    return "\n".join(lines)


def _points(c) -> str:
    """The difference from the control in points, with its 95% interval."""
    lo, hi = c.difference_ci
    return f"{100 * c.difference:+.0f} ({100 * lo:+.0f} to {100 * hi:+.0f})"
