"""The viser server: one LoopState per session, one Page per connected tab.

Only the page itself may drive a session: every HTTP request and WebSocket upgrade is checked
by dfa_viz.app.address.PageGuard (Host and Origin) before viser sees it, and refused with 403.
Every message a tab sends is one the page sends, or viser never sees it: a GUI update sets a
control's value (a plain, finite one) and nothing else of it; what it sets is then checked
against what the page offered (dfa_viz.app.controls).
"""

from __future__ import annotations

import contextlib
import http
import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import viser
import websockets.asyncio.server

from dfa_viz.app.address import DEFAULT_PORT, PageGuard, moved_note, serving_port, url
from dfa_viz.app.args import DemoArgs, ServeArgs
from dfa_viz.app.episodes import DemoEpisodes, open_demos
from dfa_viz.app.page import Page
from dfa_viz.app.policies import Policies
from dfa_viz.app.sessions import Session
from dfa_viz.app.state import LoopState
from dfa_viz.configs import AdaptConfig
from dfa_viz.foreground import wait_then_stop
from sim import check_world_name, get_world
from sim.core import UserError, check_shift


@dataclass
class App:
    """A running page: its server, shared state and URL."""

    server: viser.ViserServer
    state: LoopState
    url: str
    pages: dict[int, Page] = field(default_factory=dict)
    stopped: bool = False

    def stop(self) -> None:
        """Stop (once): the running job first (nothing is written after), then the tabs and
        the server."""
        if self.stopped:
            return
        self.stopped = True
        self.state.close()
        for page in list(self.pages.values()):
            page.close()
        self.server.stop()


def open_state(
    *,
    world: str = "nav2d",
    session: Path | None = None,
    out: Path = Path("recordings"),
    adapt: AdaptConfig = AdaptConfig(),
    policy: str | None = None,
    weights: Path | None = None,
    demos: DemoEpisodes | None = None,
) -> LoopState:
    """The loop state of a session folder (resumed), or of a new one under out/sessions/;
    `policy` (a policy.outside spec, with finetuned `weights` for it) is diagnosed in `world`
    instead of its base policy; `demos`: the dataset whose episodes the page offers."""
    # the registered name (one world, one name: a "module:Class" names its world): an unknown
    # world is one line, before anything is created
    world = check_world_name(world)
    adapt.check(get_world(world) if adapt.finetuning.replay_looks == "painted" else None)
    sess = (
        Session.open(session, world=world)
        if session is not None
        else Session.new(Path(out) / "sessions", world=world)
    )
    try:
        for note in sess.notes:
            print(f"dfa serve: {note}", flush=True)
        policies = Policies(spec=policy, world=world, weights=weights)
        return LoopState(sess, out=out, adapt_config=adapt, policies=policies, demos=demos)
    except BaseException:
        sess.close()
        raise


_serve_lock = threading.Lock()  # one guarded server starts at a time (see _guarded)
_REPORTED = 20  # refusals printed per server; more are refused silently


@contextlib.contextmanager
def _guarded(guard: PageGuard) -> Iterator[None]:
    """While a ViserServer is being constructed, make the websockets server it starts check
    every request with `guard` first.

    viser 1.1.1 has no hook for this: its server thread calls
    `websockets.asyncio.server.serve(..., process_request=<its file server>)`, and the
    constructor returns once that server is bound. So while the constructor runs, `serve` is a
    subclass that puts the guard in front of viser's process_request (a refused request gets
    403 and never reaches viser); the original is back before the constructor's caller goes on.
    Guarded starts take turns (`_serve_lock`).
    """
    original = websockets.asyncio.server.serve
    reported: list[str] = []

    def report(line: str) -> None:
        if len(reported) < _REPORTED and line not in reported:
            reported.append(line)
            print(f"dfa serve: {line}", flush=True)

    def check(connection, request):
        port = connection.local_address[1]
        why = guard.refusal(request.headers, port, upgrade="Upgrade" in request.headers)
        if not why:
            return None
        report(f"refused a request that is not from the page: {why}")
        return connection.respond(http.HTTPStatus.FORBIDDEN, f"Forbidden: {why}\n")

    def checking(handler):
        """viser's connection handler, reading only the messages the page sends."""

        async def handle(connection) -> None:
            recv = connection.recv

            async def recv_checked(*args, **kwargs):
                while True:
                    raw = await recv(*args, **kwargs)
                    why = message_refusal(raw)
                    if not why:
                        return raw
                    report(f"refused a message that is not the page's: {why}")

            connection.recv = recv_checked
            await handler(connection)

        return handle

    class GuardedServe(original):
        def __init__(self, handler, *args, process_request=None, **kwargs):
            def process(connection, request):
                refused = check(connection, request)
                if refused is not None or process_request is None:
                    return refused
                return process_request(connection, request)

            super().__init__(checking(handler), *args, process_request=process, **kwargs)

    with _serve_lock:
        websockets.asyncio.server.serve = GuardedServe
        try:
            yield
        finally:
            websockets.asyncio.server.serve = original


def message_refusal(raw: Any) -> str:
    """Why a frame from a tab is not a message the page sends ("" when it is): not one of
    viser's messages, or a GUI update that sets anything but a control's value, or a value
    that is not plain (a bool, a string, a finite number, or a flat list of those). The
    browser's page sends {"value": X} and nothing else; viser would set any other field of its
    own record of the control (its callbacks, its props) from the message."""
    if not isinstance(raw, bytes):
        return "a text frame"
    try:
        message = viser.infra.Message.deserialize(raw)
    except Exception as e:  # whatever a malformed frame makes the decoder raise
        return f"not a message viser knows ({type(e).__name__})"
    if type(message).__name__ == "GuiUpdateMessage":
        updates = message.updates
        if not isinstance(updates, dict) or set(updates) != {"value"}:
            names = ", ".join(map(str, updates)) if isinstance(updates, dict) else "?"
            return f"a control update that sets {names[:60]}, not only its value"
        if not _plain(updates["value"]):
            return "a control value that is not a bool, a string or a finite number"
    return ""


def _plain(value: Any, *, inner: bool = False) -> bool:
    if isinstance(value, bool | str):
        return True
    if isinstance(value, int):
        return abs(value) < 2**63
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, list | tuple) and not inner:
        return all(_plain(v, inner=True) for v in value)
    return False


def _quiet_refusals(who: str) -> Callable:
    """An event-loop exception handler: a tab's message that viser's own handling refuses
    (a value of the wrong type for its control: int("abc")) is one line, not a traceback."""
    reported: list[str] = []

    def handler(loop, context) -> None:
        task, error = context.get("future"), context.get("exception")
        coro = task.get_coro() if hasattr(task, "get_coro") else None
        if error is None or "handle_incoming_message" not in getattr(coro, "__qualname__", ""):
            loop.default_exception_handler(context)
            return
        why = (str(error).splitlines() or [""])[0][:120]
        line = f"{who}: refused a message from a tab: {type(error).__name__}: {why}"
        if len(reported) < _REPORTED and line not in reported:
            reported.append(line)
            print(line, flush=True)

    return handler


def open_server(
    host: str,
    port: int | None,
    chosen: int,
    note: str,
    *,
    label: str,
    who: str,
    on_fail: Callable[[], None] = lambda: None,
) -> tuple[viser.ViserServer, int]:
    """A viser server that only its own page may drive, on `chosen` (serving_port's choice
    for `port`), and the port it bound. A port given and taken between the check and the bind
    is a UserError; `on_fail` runs before any error leaves."""
    try:
        with _guarded(PageGuard(host)):
            server = viser.ViserServer(host=host, port=chosen, label=label, verbose=False)
    except BaseException:
        on_fail()
        raise
    loop = server.get_event_loop()
    loop.call_soon_threadsafe(loop.set_exception_handler, _quiet_refusals(who))
    bound = server.get_port()
    if chosen and bound != chosen:  # taken between the check and the bind
        if port is not None:
            server.stop()
            on_fail()
            raise UserError(f"port {port} is busy on {host}; choose another --port")
        note = moved_note(DEFAULT_PORT, bound)
    if note:
        print(f"{who}: {note}", flush=True)
    return server, bound


def track_pages(server: viser.ViserServer, pages: dict, make: Callable[[Any], Any]) -> None:
    """One page per connected tab: `make(client)` on connect into `pages` (by client id),
    its `close()` on disconnect."""
    lock = threading.Lock()

    @server.on_client_connect
    def _(client: viser.ClientHandle) -> None:
        page = make(client)
        with lock:
            pages[client.client_id] = page

    @server.on_client_disconnect
    def _(client: viser.ClientHandle) -> None:
        with lock:
            page = pages.pop(client.client_id, None)
        if page is not None:
            page.close()


def start(
    *,
    world: str = "nav2d",
    port: int | None = None,
    host: str = "127.0.0.1",
    session: Path | None = None,
    out: Path = Path("recordings"),
    adapt: AdaptConfig = AdaptConfig(),
    state: LoopState | None = None,
) -> App:
    """Start serving (non-blocking) and print the URL; `App.stop()` ends it.

    `port`: None serves on 8080 or the next free port (and says so); a port given must be free
    (0: any free port). Host and port are checked before a session folder is opened: bad ones
    raise UserError and create nothing.
    """
    chosen, note = serving_port(host, port)
    if state is None:
        state = open_state(world=world, session=session, out=out, adapt=adapt)
    server, bound = open_server(
        host, port, chosen, note, label="DFA", who="dfa serve", on_fail=state.close
    )
    server.gui.configure_theme(show_share_button=False, brand_color=(28, 126, 214))
    app = App(server, state, url(host, bound))
    track_pages(server, app.pages, lambda client: Page(client, state))
    print(f"dfa serve: the page is at {app.url}", flush=True)
    print(f"dfa serve: session {state.session.folder}", flush=True)
    return app


def wait_idle(state: LoopState, *, timeout_s: float = 600.0) -> None:
    """Block until no job runs; raise the job's error, if it left one."""
    state.jobs.wait(timeout_s)


def serve(args: ServeArgs) -> None:
    """Serve the page until interrupted (Ctrl-C); the session folder keeps everything."""
    serving_port(args.host, args.port)  # a bad --host or --port: before any folder is made
    demos = open_demos(args.demos)  # a bad --demos folder too
    state = open_state(
        world=args.world,
        session=args.session,
        out=args.out,
        adapt=args.adapt,
        policy=args.policy,
        weights=args.weights,
        demos=demos,
    )
    app = start(port=args.port, host=args.host, state=state)
    _block(app)


def demo(args: DemoArgs, *, block: bool = True) -> App:
    """Open the page on a default scenario with the diagnosis already computed: the task is
    loaded, judged failed, demonstrated by the expert and searched before the URL is printed.
    Host and port are checked first (as in `start`), before any session folder is made."""
    serving_port(args.host, args.port)
    check_shift(args.shift)
    state = open_state(world=args.world, out=args.out, adapt=args.adapt)
    try:
        world = state.world_name  # as the registry names it
        print(f"dfa demo: preparing {world} / {args.shift} / seed {args.seed}…", flush=True)
        state.pick(world, args.shift, args.seed)
        wait_idle(state)
        state.judge(True)
        state.demonstrate(expert=True)
        wait_idle(state)
    except BaseException:
        state.close()
        raise
    app = start(port=args.port, host=args.host, state=state)
    if block:
        _block(app)
    return app


def _block(app: App) -> None:
    """Serve until Ctrl-C or SIGTERM, then stop (a running job is cancelled: its step is
    offered again on resume) and say where the session is."""
    folder = app.state.session.folder
    wait_then_stop(app.stop, stopped=f"dfa serve: stopped; the session is saved in {folder}")
