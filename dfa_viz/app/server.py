"""The viser server: one LoopState per session, one Page per connected tab."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import viser

from dfa_viz.app.page import Page
from dfa_viz.app.sessions import Session
from dfa_viz.app.state import LoopState
from sim import WORLDS
from sim.core import UserError, check_shift


@dataclass
class App:
    """A running page: its server, shared state and URL."""

    server: viser.ViserServer
    state: LoopState
    url: str
    pages: dict[int, Page] = field(default_factory=dict)

    def stop(self) -> None:
        for page in list(self.pages.values()):
            page.close()
        self.server.stop()
        self.state.close()


def _check_world(world: str) -> None:
    if world not in WORLDS:
        raise UserError(f"unknown world {world!r}; accepted: {', '.join(WORLDS)}")


def open_state(
    *,
    world: str = "nav2d",
    session: Path | None = None,
    out: Path = Path("recordings"),
    finetune_steps: int | None = None,
) -> LoopState:
    """The loop state of a session folder (resumed), or of a new one under out/sessions/."""
    _check_world(world)
    sess = (
        Session.open(session, world=world)
        if session is not None
        else Session.new(Path(out) / "sessions", world=world)
    )
    try:
        for note in sess.notes:
            print(f"dfa serve: {note}", flush=True)
        return LoopState(sess, out=out, finetune_steps=finetune_steps)
    except BaseException:
        sess.close()
        raise


def start(
    *,
    world: str = "nav2d",
    port: int = 8080,
    host: str = "127.0.0.1",
    session: Path | None = None,
    out: Path = Path("recordings"),
    finetune_steps: int | None = None,
    state: LoopState | None = None,
) -> App:
    """Start serving (non-blocking) and print the URL; `App.stop()` ends it."""
    if state is None:
        state = open_state(world=world, session=session, out=out, finetune_steps=finetune_steps)
    try:
        server = viser.ViserServer(host=host, port=port, label="DFA", verbose=False)
    except OSError as e:
        state.close()
        raise UserError(f"cannot serve on {host}:{port} ({e.strerror})") from None
    server.gui.configure_theme(show_share_button=False, brand_color=(28, 126, 214))
    app = App(server, state, f"http://{host}:{server.get_port()}")
    worlds = tuple(WORLDS)
    lock = threading.Lock()

    @server.on_client_connect
    def _(client: viser.ClientHandle) -> None:
        page = Page(client, state, worlds)
        with lock:
            app.pages[client.client_id] = page

    @server.on_client_disconnect
    def _(client: viser.ClientHandle) -> None:
        with lock:
            page = app.pages.pop(client.client_id, None)
        if page is not None:
            page.close()

    print(f"dfa serve: the page is at {app.url}", flush=True)
    print(f"dfa serve: session {state.session.folder}", flush=True)
    return app


def wait_idle(state: LoopState, *, timeout_s: float = 600.0) -> None:
    """Block until no job runs; raise the job's error, if it left one."""
    deadline = time.monotonic() + timeout_s
    while state.busy:
        if time.monotonic() > deadline:
            raise TimeoutError(
                f"a {state.job.name if state.job else ''} job took over {timeout_s} s"
            )
        time.sleep(0.05)
    if state.error:
        raise UserError(state.error)


def serve(
    *,
    world: str = "nav2d",
    port: int = 8080,
    host: str = "127.0.0.1",
    session: Path | None = None,
    out: Path = Path("recordings"),
) -> None:
    """Serve the page until interrupted (Ctrl-C); the session folder keeps everything."""
    app = start(world=world, port=port, host=host, session=session, out=out)
    _block(app)


def demo(
    world: str = "nav2d",
    shift: str = "distractor_ti",
    seed: int = 0,
    *,
    port: int = 8080,
    host: str = "127.0.0.1",
    out: Path = Path("recordings"),
    block: bool = True,
) -> App:
    """Open the page on a default scenario with the diagnosis already computed: the task is
    loaded, judged failed, demonstrated by the expert and searched before the URL is printed."""
    check_shift(shift)
    state = open_state(world=world, out=out)
    try:
        print(f"dfa demo: preparing {world} / {shift} / seed {seed}…", flush=True)
        state.pick(world, shift, seed)
        wait_idle(state)
        state.judge(True)
        state.demonstrate(expert=True)
        wait_idle(state)
    except BaseException:
        state.close()
        raise
    app = start(port=port, host=host, state=state)
    if block:
        _block(app)
    return app


def _block(app: App) -> None:
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
        print(f"dfa serve: stopped; the session is saved in {app.state.session.folder}", flush=True)
