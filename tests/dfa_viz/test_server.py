"""`dfa serve` and `dfa demo`: bad --host/--port, busy ports, and only the page drives a session.

Real servers on real sockets: the page is started with dfa_viz.app.start and spoken to with
raw HTTP over a socket and with the websockets client library.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import viser
import websockets.asyncio.server
import websockets.exceptions
import websockets.sync.client
from page_wire import free_port

from dfa_viz.app.address import DEFAULT_PORT, PageGuard, serving_port
from sim.core import UserError

SUBPROTOCOL = f"viser-v{viser.__version__}"  # what the page's client asks for
SERVE = websockets.asyncio.server.serve  # start() swaps it only while viser binds


def _files(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file's bytes and mtime under folder."""
    return {
        str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


# `python -m dfa_viz.cli ARGS`, then (at exit, on stdout) which of the heavy packages it imported
HEAVY = ("torch", "viser", "mujoco", "rerun")
DFA_IMPORTING = f"""
import atexit, json, runpy, sys
atexit.register(lambda: print("imported:", json.dumps([m for m in {HEAVY!r} if m in sys.modules])))
runpy.run_module("dfa_viz.cli", run_name="__main__", alter_sys=True)
"""


def _dfa(*args: str, cwd: Path) -> tuple[subprocess.CompletedProcess, list[str]]:
    """The command's result, and the heavy packages it imported before it ended."""
    proc = subprocess.run(
        [sys.executable, "-c", DFA_IMPORTING, *args],
        capture_output=True,
        text=True,
        timeout=600,  # a ceiling for a hung command, not an expectation
        cwd=cwd,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    lines = [x for x in proc.stdout.splitlines() if x.startswith("imported: ")]
    assert len(lines) == 1, proc.stdout
    return proc, json.loads(lines[0].removeprefix("imported: "))


# -- bad --host / --port: one line, exit 2, nothing created -------------------------------------
ACCEPTED_HOSTS = (
    "accepted: 127.0.0.1 (the default), localhost, ::1, 0.0.0.0 (every interface) "
    "or an address of this machine"
)
BAD = [
    (
        ["--port", "70000"],
        "dfa: error: --port 70000 is not a port number; accepted: 1 to 65535, "
        "or 0 for any free port",
    ),
    (
        ["--port", "-1"],
        "dfa: error: --port -1 is not a port number; accepted: 1 to 65535, or 0 for any free port",
    ),
    (
        ["--host", "10.123.45.67"],
        "dfa: error: --host '10.123.45.67' is not an address of this machine "
        f"(Cannot assign requested address); {ACCEPTED_HOSTS}",
    ),
    (
        ["--host", "no-such-host.invalid"],
        "dfa: error: --host 'no-such-host.invalid' is not an address of this machine "
        f"(Name or service not known); {ACCEPTED_HOSTS}",
    ),
]


@pytest.mark.parametrize("command", ["serve", "demo"])
@pytest.mark.parametrize(("args", "line"), BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_host_or_port_is_one_line_at_once_and_creates_nothing(tmp_path, command, args, line):
    proc, imported = _dfa(command, *args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines() == [line]
    assert "Traceback" not in proc.stdout + proc.stderr
    assert list(tmp_path.iterdir()) == []  # no recordings/, no session folder
    assert imported == []  # checked before the server (torch, viser, MuJoCo) is imported


def test_an_explicit_busy_port_is_an_error(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc, _ = _dfa("serve", "--port", str(port), cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [
        f"dfa: error: port {port} is busy on 127.0.0.1; choose another --port, or leave --port "
        f"out to take the next free one after {DEFAULT_PORT}"
    ]
    assert list(tmp_path.iterdir()) == []


def test_python_callers_get_the_same_checks(tmp_path):
    from dfa_viz.app import start

    for port, host in ((70000, "127.0.0.1"), (0, "10.123.45.67"), (0, "a" * 64), (0, "a\0b")):
        with pytest.raises(UserError):
            start(port=port, host=host, session=tmp_path / "s", out=tmp_path)
    assert list(tmp_path.iterdir()) == []


def _hold_ports_from_default() -> list[socket.socket]:
    """Listen on 8080 and on every port after it up to the first that was free: without
    --port the server has to move past all of them."""
    held = []
    for port in range(DEFAULT_PORT, DEFAULT_PORT + 50):
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:  # already busy (another program): the server must pass it too
            s.close()
            continue
        s.listen()
        held.append(s)
        return held
    pytest.fail("ports 8080-8129 are all busy: nothing to hold for the test")


def test_without_port_a_busy_8080_moves_on_and_says_so(tmp_path, capsys):
    from dfa_viz.app import start

    held = _hold_ports_from_default()
    taken = held[-1].getsockname()[1]
    port, note = serving_port("127.0.0.1", None)
    assert port > taken and note == f"port {DEFAULT_PORT} is busy; serving on {port}"
    app = start(session=tmp_path / "s", out=tmp_path)
    try:
        served = app.server.get_port()
        assert served > taken
        assert app.url == f"http://127.0.0.1:{served}"
        out = capsys.readouterr().out
        assert f"dfa serve: port {DEFAULT_PORT} is busy; serving on {served}\n" in out
    finally:
        app.stop()
        for s in held:
            s.close()


# -- only the page drives a session -------------------------------------------------------------
def _request(port: int, *, host: str, origin: str | None, upgrade: bool = True) -> int:
    """The HTTP status of one raw request to the server on 127.0.0.1:port."""
    lines = ["GET / HTTP/1.1", f"Host: {host}"]
    if upgrade:
        key = base64.b64encode(os.urandom(16)).decode()
        lines += [
            "Upgrade: websocket",
            "Connection: Upgrade",
            f"Sec-WebSocket-Key: {key}",
            "Sec-WebSocket-Version: 13",
            f"Sec-WebSocket-Protocol: {SUBPROTOCOL}",
        ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=300) as s:  # a ceiling
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        head = b""
        while b"\r\n" not in head:
            chunk = s.recv(4096)
            if not chunk:
                break
            head += chunk
    return int(head.split(b" ", 2)[1])


@pytest.fixture
def page(tmp_path):
    """A served page (no task loaded) and its session log."""
    from dfa_viz.app import start

    app = start(port=free_port(), session=tmp_path / "s", out=tmp_path / "rec")
    yield app, app.server.get_port(), tmp_path / "s" / "session.jsonl"
    app.stop()


def test_foreign_origins_and_hosts_are_refused_before_the_socket_opens(page):
    app, port, log = page
    other = free_port()
    before = _files(log.parent)
    own = f"http://127.0.0.1:{port}"
    for host, origin in [
        (f"127.0.0.1:{port}", f"http://evil.example:{port}"),  # another site
        (f"127.0.0.1:{port}", f"http://evil.example:{DEFAULT_PORT}"),
        (f"127.0.0.1:{port}", f"http://127.0.0.1:{other}"),  # another local page
        (f"127.0.0.1:{port}", "null"),  # a sandboxed frame or a file:// page
        (f"127.0.0.1:{port}", None),  # no Origin: not a browser's page
        (f"evil.example:{port}", own),  # DNS rebinding: the site's name, this address
        (f"evil.example:{port}", f"http://evil.example:{port}"),
        (f"127.0.0.1:{other}", own),
    ]:
        assert _request(port, host=host, origin=origin) == 403, (host, origin)
    # the page's files are not served under a foreign Host either
    assert _request(port, host=f"evil.example:{port}", origin=None, upgrade=False) == 403
    with pytest.raises(websockets.exceptions.InvalidStatus) as refused:
        websockets.sync.client.connect(
            f"ws://127.0.0.1:{port}", origin="http://evil.example", subprotocols=[SUBPROTOCOL]
        )
    assert refused.value.response.status_code == 403
    assert not app.pages
    assert _files(log.parent) == before  # the session log is as it was


def test_the_pages_own_origin_is_accepted(page):
    _, port, _ = page
    for name in ("127.0.0.1", "localhost"):
        assert _request(port, host=f"{name}:{port}", origin=f"http://{name}:{port}") == 101
    assert _request(port, host=f"127.0.0.1:{port}", origin=None, upgrade=False) == 200
    with websockets.sync.client.connect(
        f"ws://127.0.0.1:{port}", origin=f"http://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL]
    ) as ws:
        assert ws.subprotocol == SUBPROTOCOL
    assert websockets.asyncio.server.serve is SERVE  # other servers in the process unchanged


def test_page_guard_names():
    """Which Host/Origin pairs are the page's, without a server (port 8123)."""
    port = 8123

    def ok(guard: PageGuard, host: str, origin: str | None = "same") -> bool:
        if origin == "same":
            origin = f"http://{host}"
        headers = {"Host": host} if origin is None else {"Host": host, "Origin": origin}
        return guard.refusal(headers, port, upgrade=True) == ""

    loopback = PageGuard("127.0.0.1")
    assert ok(loopback, f"127.0.0.1:{port}")
    assert ok(loopback, f"localhost:{port}")
    assert ok(loopback, f"[::1]:{port}")
    assert ok(loopback, f"LOCALHOST:{port}")  # names are not case-sensitive
    assert not ok(loopback, "127.0.0.1")  # port 80
    assert not ok(loopback, f"127.0.0.1:{port}", f"https://127.0.0.1:{port + 1}")
    assert not ok(loopback, f"127.0.0.1:{port}", f"http://user@127.0.0.1:{port}")
    assert not ok(loopback, f"127.0.0.1:{port}", f"http://127.0.0.1:{port}/x")
    assert not ok(loopback, f"127.0.0.1:{port}", f"ftp://127.0.0.1:{port}")
    assert not ok(loopback, f"127.0.0.1:{port}@evil.example")
    assert not ok(loopback, f"127.0.0.1:{port}", f"http://127.0.0.1:{port}.evil.example")
    assert not ok(loopback, f"127.0.0.1:{port}", None)
    assert not ok(loopback, f"127.0.0.1:{port}", "http://[::1")  # malformed: refused, no error
    assert not ok(loopback, f"[::1:{port}")
    assert not ok(loopback, f"{socket.gethostname()}:{port}")  # only with --host 0.0.0.0
    # without upgrade (the page's files), Origin is not needed; Host still is
    assert loopback.refusal({"Host": f"127.0.0.1:{port}"}, port, upgrade=False) == ""
    assert loopback.refusal({}, port, upgrade=False) == "no Host header (or more than one)"

    named = PageGuard("my-machine.lan")  # --host my-machine.lan: that name too
    assert ok(named, f"my-machine.lan:{port}") and ok(named, f"127.0.0.1:{port}")
    assert not ok(named, f"other.lan:{port}")

    every = PageGuard("0.0.0.0")  # every interface: any address this machine has
    assert ok(every, f"127.0.0.1:{port}")
    assert ok(every, f"0.0.0.0:{port}")
    assert ok(every, f"{socket.gethostname()}:{port}")
    assert not ok(every, f"10.123.45.67:{port}")  # not an address of this machine
    assert not ok(every, f"evil.example:{port}")  # a name is never resolved
    assert not ok(every, f"127.0.0.1:{port + 1}")
    mine = _an_address_of_this_machine()
    if mine is not None:
        assert ok(every, f"{mine}:{port}")
        assert not ok(loopback, f"{mine}:{port}")


def _an_address_of_this_machine() -> str | None:
    """A non-loopback IPv4 address of this machine, if it has one."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("10.255.255.255", 1))  # no packet is sent; picks the outgoing address
            address = s.getsockname()[0]
    except OSError:
        return None
    return None if address.startswith("127.") else address


def test_a_world_named_as_module_class_is_offered_once_by_its_own_name(tmp_path, monkeypatch):
    """`dfa serve --world corridor:CorridorWorld` serves the world registered as "corridor":
    the session and the world picker name it once, by that name."""
    from dfa_viz.app.server import open_state

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "docs" / "examples"))
    state = open_state(world="corridor:CorridorWorld", session=tmp_path / "s", out=tmp_path)
    try:
        assert state.world_name == "corridor"
        assert state.worlds.count("corridor") == 1
        assert not [w for w in state.worlds if w.startswith("corridor:")]
        header = json.loads((tmp_path / "s" / "session.jsonl").read_text().splitlines()[0])
        assert header["world"] == "corridor"
    finally:
        state.close()
