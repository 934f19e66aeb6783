"""`dfa study serve DIR`: the study page, one participant per tab, many at once.

The server binds 127.0.0.1 unless told otherwise and accepts only requests from its own page
(dfa_viz.app.address.PageGuard, as `dfa serve`). It reads the frozen tasks and the
familiarisation's pictures, never truth.json. Only the participant codes issued by
`dfa study new` (codes.txt) are accepted.
"""

from __future__ import annotations

import threading
from pathlib import Path

from dfa_viz.app.address import serving_port, url
from dfa_viz.app.server import App, open_server, track_pages
from dfa_viz.foreground import wait_then_stop
from dfa_viz.study.answers import Store, check_id
from dfa_viz.study.codes import issued, read_codes
from dfa_viz.study.freeze import FrozenTask, load_intro, load_study, load_task
from dfa_viz.study.page import StudyPage
from dfa_viz.study.protocol import Question
from sim.core import UserError


class Study:
    """What every tab of one study shares: the protocol, the frozen tasks, the answers, and
    which participant codes are open in a tab now."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.protocol, self.index = load_study(self.folder)
        self.store = Store(self.folder, self.protocol)
        self.codes = read_codes(self.folder)
        self._tasks: dict[str, FrozenTask] = {}
        self._intro: dict[str, dict] = {}
        self._open: dict[str, StudyPage] = {}
        self._lock = threading.Lock()
        for world, _ in self.protocol.tasks:  # read everything once, up front
            self.intro(world)
        for shifts in self.index.values():
            for tid in shifts.values():
                self._tasks[tid] = load_task(self.folder, tid)

    def task(self, q: Question) -> FrozenTask:
        return self._tasks[self.index[q.slot.key][q.shift]]

    def intro(self, world: str) -> dict:
        if world not in self._intro:
            self._intro[world] = load_intro(self.folder, world)
        return self._intro[world]

    def claim(self, typed: str, page: StudyPage) -> str:
        """The issued code `typed` names, now held by `page` (a code not issued, or open in
        another tab: a one-line UserError). A code already used resumes its participant."""
        pid = check_id(issued(self.codes, typed))
        with self._lock:
            holder = self._open.get(pid)
            if holder is not None and holder is not page:
                raise UserError(f"code {pid} is open in another window; close that one first")
            self._open[pid] = page
        return pid

    def release(self, pid: str, page: StudyPage) -> None:
        with self._lock:
            if self._open.get(pid) is page:
                del self._open[pid]

    def close(self) -> None:
        """Nothing to release: every answer is on disk when it is given (App.stop calls it)."""


def start_study(folder: Path, *, port: int | None = None, host: str = "127.0.0.1") -> App:
    """Serve the study in `folder` (non-blocking) and print the URL; App.stop() ends it
    (App.state is the Study)."""
    chosen, note = serving_port(host, port)
    study = Study(folder)
    server, bound = open_server(host, port, chosen, note, label="Study", who="dfa study")
    server.gui.configure_theme(show_share_button=False, brand_color=(28, 126, 214))
    app = App(server, study, url(host, bound))
    track_pages(server, app.pages, lambda client: StudyPage(client, study))
    print(f"dfa study: the page is at {app.url}", flush=True)
    return app


def serve_study(folder: Path, *, port: int | None = None, host: str = "127.0.0.1") -> None:
    """Serve until Ctrl-C; every answer is already on disk."""
    app = start_study(folder, port=port, host=host)
    answers = Path(folder) / "answers"
    wait_then_stop(app.stop, stopped=f"dfa study: stopped; the answers are in {answers}")
