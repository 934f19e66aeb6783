"""The compare panel of one tab: failed | demonstration | counterfactual (| finetuned), frame-
synced under one timeline slider with play/pause, step and speed, and the action-distance
trace with the current step marked. The slider position belongs to the tab, not the session.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import viser

from dfa_viz.app import frames, plots
from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View

SPEEDS = {"0.5×": 0.5, "1×": 1.0, "2×": 2.0, "4×": 4.0}
BASE_FPS = 4.0  # frames per second at 1×
PLAYBACK = ("« start", "◀ step", "▶ play", "❚❚ pause", "step ▶")
CAPTION_COLOURS = {
    "failed": (217, 72, 15),
    "demonstration": (134, 142, 150),
    "counterfactual": (47, 158, 68),
    "finetuned": (28, 126, 214),
}


class ComparePanel:
    def __init__(self, client: viser.ClientHandle, state: LoopState, on_step=None) -> None:
        self.client, self.state, self.on_step = client, state, on_step
        self._lock = threading.RLock()
        self._view: View | None = None
        self._key: tuple | None = None
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
            self.slider = gui.add_slider("step", min=0, max=1, step=1, initial_value=0)
            self.playback = gui.add_button_group("playback", PLAYBACK)
            self.speed = gui.add_dropdown("speed", tuple(SPEEDS), initial_value="1×")
            data, series, scales = plots.distance_plot(_dummy_world(), None, {}, 0)
            self.trace = gui.add_uplot(
                data,
                series,
                scales=scales,
                title="action distance to the demonstration",
                aspect=2.0,
            )
        self.panel.dock_right()
        self.panel.set_width(700)
        self.slider.on_update(lambda _: self.show())
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
            if self.slider.max != horizon:
                self.slider.max = horizon
                if self.slider.value > horizon:
                    self.slider.value = 0
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
        cols = [
            ("failed", frames.frame_at(run.rollout, step), "", CAPTION_COLOURS["failed"]),
            (
                "demonstration",
                frames.frame_at(run.demo, step),
                "no demonstration yet",
                CAPTION_COLOURS["demonstration"],
            ),
            (
                "counterfactual",
                frames.frame_at(counterfactual, step),
                cf_missing,
                CAPTION_COLOURS["counterfactual"],
            ),
        ]
        if run.adaptation is not None:
            cols.append(
                (
                    "finetuned",
                    frames.frame_at(run.adaptation.rollout, step),
                    "",
                    CAPTION_COLOURS["finetuned"],
                )
            )
        return cols

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
            data, series, scales = plots.distance_plot(view.world, run.demo, traces, step)
            with self.client.atomic():
                self.image.image = image
                if len(self.trace.series) != len(series) or force:
                    self.trace.series = series
                    self.trace.scales = scales
                self.trace.data = data
            self.client.flush()
        if self.on_step is not None:
            self.on_step(view, step)

    # -- playback -----------------------------------------------------------------------------
    def _on_playback(self, event) -> None:
        value = event.target.value
        top = int(self.slider.max)
        if value == "▶ play":
            if int(self.slider.value) >= top:
                self.slider.value = 0
            self._playing.set()
        elif value == "❚❚ pause":
            self._playing.clear()
        else:
            self._playing.clear()
            cur = int(self.slider.value)
            new = {"« start": 0, "◀ step": cur - 1, "step ▶": cur + 1}[value]
            self.slider.value = int(np.clip(new, 0, top))

    def _play_loop(self) -> None:
        while not self._closed.is_set():
            if not self._playing.wait(timeout=0.5):
                continue
            time.sleep(1.0 / (BASE_FPS * SPEEDS.get(self.speed.value, 1.0)))
            if not self._playing.is_set():
                continue
            cur, top = int(self.slider.value), int(self.slider.max)
            if cur >= top:
                self._playing.clear()
            else:
                self.slider.value = cur + 1

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
