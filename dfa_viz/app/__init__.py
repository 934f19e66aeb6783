"""The feedback web page (viser): pick a task, demonstrate, diagnose, mark TI/TR, adapt, share.

    serve(world=, port=, host=, session=)   serve until Ctrl-C (`dfa serve`)
    demo(world=, shift=, seed=)             the page on a default scenario, diagnosis computed
    start(...) -> App                       non-blocking (tests, benchmarks); App.stop()

Modules: args (ServeArgs, DemoArgs: the options of `dfa serve` and `dfa demo`), sessions (the
JSON-lines session folder), events (the session's typed events), replay (an event applied to
the run record: the loop's step), runstate (the run, its log and recording), state (the user's
actions, each a loop step and an event), hub (ordered input, subscribers), offers (what the
page accepts), policies, recorder, jobs (one long job at a time), demonstrate (per-world
input), episodes (a LeRobotDataset's episodes offered as demonstrations, `dfa serve --demos`),
frames and plots (what is drawn), page/task_section/compare/feedback/canvas/tables/picker (one
tab's GUI), server.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dfa_viz.app.server import App, demo, serve, start

__all__ = ["App", "demo", "serve", "start"]


def __getattr__(name: str) -> Any:
    # Importing the package stays light (the CLI imports it on `dfa serve` only).
    if name in __all__:
        from dfa_viz.app import server

        return getattr(server, name)
    raise AttributeError(name)
