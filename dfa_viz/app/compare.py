"""The compare panel of one tab: failed | demonstration | counterfactual (| finetuned), frame-
synced under one timeline slider with play/pause, step and speed, and the action-distance
trace with the current step marked. The slider position belongs to the tab, not the session,
and so does the saliency overlay: a captum method's maps of the failed rollout (against the
demonstration) blended into its frames, beside the counterfactual (dfa_viz.overlay).
"""

from __future__ import annotations

import threading
import time

import numpy as np
import viser

from dfa_viz import charts
from dfa_viz.app import frames, plots
from dfa_viz.app.controls import Checked, one_of, refusal, refuse, whole
from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View
from dfa_viz.overlay import SaliencyLayer, blend, failed_saliency
from policy.methods import METHOD_NAMES
from search import distance_to_demo
from sim.core import UserError

SPEEDS = {"0.5×": 0.5, "1×": 1.0, "2×": 2.0, "4×": 4.0}
BASE_FPS = 4.0  # frames per second at 1×
PANEL_PX = 620  # the compare panel's width: the 3D view keeps the middle
PLAYBACK = ("« start", "◀ step", "▶ play", "❚❚ pause", "step ▶")
SALIENCY_OFF = "off"
SALIENCY = {SALIENCY_OFF: None, **{name: method for method, name in METHOD_NAMES.items()}}


class ComparePanel:
    def __init__(self, client: viser.ClientHandle, state: LoopState, on_step=None) -> None:
        self.client, self.state, self.on_step = client, state, on_step
        self._lock = threading.RLock()
        self._view: View | None = None
        self._key: tuple | None = None
        self._bars_key: tuple | None = None
        self._overlay: tuple | None = None  # (rollout, demo, method, layer or None, note)
        self._playing = threading.Event()
        self._closed = threading.Event()
        gui = client.gui
        self.panel = gui.add_panel()
        with self.panel.add_tab("Compare", viser.Icon.LAYOUT_COLUMNS):
            self.title = gui.add_markdown("Pick a task to start.")
            self.image = gui.add_image(
                np.full((frames.FRAME_PX, frames.FRAME_PX, 3), 240, np.uint8),
                label="frames",
                format="png",
            )
            slider = gui.add_slider("step", min=0, max=1, step=1, initial_value=0)
            self.slider = Checked(
                slider, whole(0, lambda: int(slider.max)), client, lambda _: self.show()
            )
            self.playback = gui.add_button_group("playback", PLAYBACK)
            speed = gui.add_dropdown("speed", tuple(SPEEDS), initial_value="1×")
            self.speed = Checked(speed, one_of(lambda: tuple(SPEEDS)), client)
            saliency = gui.add_dropdown(
                "saliency",
                tuple(SALIENCY),
                initial_value=SALIENCY_OFF,
                hint="Overlay where the failed rollout's frames push the policy away from the "
                "demonstration (captum)",
            )
            self.saliency_note = gui.add_markdown("", visible=False)
            data, series, scales = plots.distance_plot(_dummy_world(), None, {}, 0)
            self.trace = gui.add_uplot(
                data,
                series,
                scales=scales,
                axes=plots.DISTANCE_AXES,
                legend=plots.LEGEND,
                title="action distance to the demonstration",
                aspect=2.0,
            )
            # one-step worlds: a bar per rollout against the bound instead of one-point curves
            self.bars = gui.add_image(
                np.full((8, 8, 3), 255, np.uint8), label="distance", format="png", visible=False
            )
        self.panel.dock_right()
        self.panel.set_width(PANEL_PX)
        self.saliency = Checked(
            saliency, one_of(lambda: tuple(SALIENCY)), client, lambda _: self.show(force=True)
        )
        self.playback.on_click(self._on_playback)
        self._player = threading.Thread(target=self._play_loop, daemon=True)
        self._player.start()

    # -- drawing ------------------------------------------------------------------------------
    def refresh(self, view: View) -> None:
        """New state: reset the slider range and redraw the current step."""
        with self._lock:
            self._view = view
            rec = view.record
            if rec is None:
                return
            horizon = view.world.horizon
            if self.slider.handle.max != horizon:
                self.slider.handle.max = horizon
                if self.slider.value > horizon:
                    self.slider.set(0)
            ev = rec.evaluation
            self.title.content = (
                f"**{rec.world} · {rec.shift} · seed {rec.seed}** — "
                f"“{rec.task.reward.instruction}”"
                + (
                    f"  \nSuccess on {len(ev.before.shifted)} fresh tasks with the shift: "
                    f"**{ev.before.on_shift:.0%} → {ev.after.on_shift:.0%}** after finetuning"
                    if ev is not None
                    else ""
                )
            )
            self.show(force=True)

    def columns(self, view: View, step: int):
        run = view.record
        counterfactual = run.diagnosis.counterfactual if run.diagnosis else None
        cf_missing = {
            "judge": "after your demonstration",
            "solved": "nothing to diagnose",
            "demonstrate": "after your demonstration",
            "diagnose": "searching…",
        }.get(view.stage, "no counterfactual found")
        # the policy's own rollout is "failed" once the user said so
        policy = "failed" if run.failed else "the policy"
        shown = [
            (policy, run.rollout, ""),
            ("demonstration", run.demo, "no demonstration yet"),
            ("counterfactual", counterfactual, cf_missing),
        ]
        if run.adaptation is not None:
            shown.append(("finetuned", run.adaptation.rollout, ""))
        layer = self._saliency(view)
        cols = []
        for name, traj, missing in shown:
            title = name + ("" if traj is None else (" ✓" if traj.success else " ✗"))
            frame = frames.frame_at(traj, step)
            colour = tuple(charts.rgb("failed" if name == policy else name))
            if name == policy and layer is not None:
                title += f" · {METHOD_NAMES[layer.method]}"
                if frame is not None and step < len(layer.maps):
                    frame = blend(frame, layer.maps[step])
            if frame is not None and step == 0 and view.world.demo_input == "pick_place":
                frame = frames.mark_pick_place(view.world, frame, traj.actions[0], colour)
            cols.append((title, frame, missing, colour))
        return cols

    def _saliency(self, view: View) -> SaliencyLayer | None:
        """The chosen method's maps of the failed rollout, computed once per rollout,
        demonstration and method; the note under the dropdown says what they show."""
        run, method = view.record, SALIENCY.get(self.saliency.value)
        if method is None:
            self.saliency_note.visible = False
            return None
        cached = self._overlay
        same = cached is not None and cached[0] is run.rollout and cached[1] is run.demo
        if not same or cached[2] != method:
            note, layer = "", None
            try:
                policy = self.state.policies.get(view.world)
                layer = failed_saliency(view.world, policy, run, method)
            except UserError as e:
                note = str(e)
            if layer is None and not note:
                note = "The saliency of the failed rollout is shown after your demonstration."
            elif layer is not None:
                note = (
                    f"{METHOD_NAMES[method]}: where the failed rollout's frames push the "
                    "policy's action away from the demonstration's (brighter is more)."
                )
            cached = self._overlay = (run.rollout, run.demo, method, layer, note)
        self.saliency_note.content = cached[4]
        self.saliency_note.visible = True
        return cached[3]

    def show(self, *, force: bool = False) -> None:
        """Draw the frames and the trace marker at the slider's step."""
        with self._lock:
            view = self._view
            if view is None or view.record is None:
                return
            run = view.record
            step = int(self.slider.value)
            key = (view.version, step)
            if key == self._key and not force:
                return
            self._key = key
            image = frames.strip(
                self.columns(view, step),
                frame_shape=view.world.obs_shape,
                footer=f"step {step} / {view.world.horizon}",
            )
            cf = run.diagnosis.counterfactual if run.diagnosis else None
            traces = {"failed": run.rollout, "counterfactual": cf}
            if run.adaptation is not None:
                traces["finetuned"] = run.adaptation.rollout
            one_step = view.world.horizon == 1
            res = run.diagnosis.result if run.diagnosis else None
            bound = res.epsilon if res is not None and res.tightened else None
            data, series, scales = plots.distance_plot(view.world, run.demo, traces, step, bound)
            with self.client.atomic():
                self.image.image = image
                self.trace.visible = not one_step
                if one_step:
                    self._draw_bars(view, traces, force=force)
                else:
                    if self.trace.series != series or force:  # labels carry the step's values
                        self.trace.series = series
                    self.trace.scales = scales
                    self.trace.data = data
            self.client.flush()
        if self.on_step is not None:
            self.on_step(view, step)

    def _draw_bars(self, view: View, traces: dict, *, force: bool) -> None:
        """One-step worlds: each rollout's distance to the demonstration, a bar against ε."""
        run = view.record
        key = (view.version, "bars")
        if run.demo is None:
            self.bars.visible = False
            return
        if key == self._bars_key and not force:
            return
        self._bars_key = key
        values = {
            name: float(np.nansum(distance_to_demo(view.world, traj, run.demo)))
            for name, traj in traces.items()
            if traj is not None
        }
        self.bars.image = charts.distance_bars(values, view.world.epsilon)
        self.bars.visible = True

    # -- playback -----------------------------------------------------------------------------
    def _on_playback(self, event) -> None:
        value = event.target.value
        if value not in PLAYBACK:
            refuse(self.client, refusal("playback", value, f"accepted: {', '.join(PLAYBACK)}"))
            return
        top = int(self.slider.handle.max)
        if value == "▶ play":
            if int(self.slider.value) >= top:
                self.slider.set(0)
            self._playing.set()
        elif value == "❚❚ pause":
            self._playing.clear()
        else:
            self._playing.clear()
            cur = int(self.slider.value)
            new = {"« start": 0, "◀ step": cur - 1, "step ▶": cur + 1}[value]
            self.slider.set(int(np.clip(new, 0, top)))

    def _play_loop(self) -> None:
        while not self._closed.is_set():
            if not self._playing.wait(timeout=0.5):
                continue
            time.sleep(1.0 / (BASE_FPS * SPEEDS.get(self.speed.value, 1.0)))
            if not self._playing.is_set():
                continue
            cur, top = int(self.slider.value), int(self.slider.handle.max)
            if cur >= top:
                self._playing.clear()
            else:
                self.slider.set(cur + 1)

    def close(self) -> None:
        self._closed.set()
        self._playing.clear()


def _dummy_world():
    """Enough of a World for an empty trace before any task is loaded."""

    class _W:
        horizon = 2
        discrete = True
        epsilon = 0.0

    return _W()
