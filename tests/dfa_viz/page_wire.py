"""One tab of the page without a browser, for tests: a WebSocket client that speaks viser
1.1.1's protocol with the page's own Origin, keeps the GUI the server sends it, and clicks
buttons and sets controls with the messages the browser sends (GuiUpdateMessage), or with
any values a forged client could send.

Server -> client: binary frames of [8 bytes msgpack size][8 bytes zstd size][zstd msgpack of
{"messages": [...]}][binary buffers]; each message a dict with its class name in "type".
Client -> server: one msgpack dict per frame, {"type": "GuiUpdateMessage", "uuid": ...,
"updates": {...}}. viser counts a client as connected once it has sent its camera.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import viser
import websockets.exceptions
import websockets.sync.client
import zstandard

CEILING_S = 1200.0  # a job takes seconds to minutes on two busy cores; this only ends a hang
SUBPROTOCOL = f"viser-v{viser.__version__}"
CAMERA = {
    "type": "ViewerCameraMessage",
    "wxyz": [1.0, 0.0, 0.0, 0.0],
    "position": [0.0, 0.0, 20.0],
    "fov": 1.0,
    "near": 0.01,
    "far": 100.0,
    "image_height": 800,
    "image_width": 1200,
    "look_at": [0.0, 0.0, 0.0],
    "up_direction": [0.0, 1.0, 0.0],
}


class PageWire:
    """A connected tab: `gui` maps each GUI element's uuid to its type, props and value, as
    the server last said; `notes` holds the notifications shown to this tab ("title: body")."""

    def __init__(self, url: str) -> None:
        port = int(url.rsplit(":", 1)[1])
        self.ws = websockets.sync.client.connect(
            f"ws://127.0.0.1:{port}",
            origin=f"http://127.0.0.1:{port}",
            subprotocols=[SUBPROTOCOL],
            max_size=None,
            open_timeout=60,
        )
        self.gui: dict[str, dict[str, Any]] = {}
        self.notes: list[str] = []
        self.messages = 0
        self.closed = False
        self._cond = threading.Condition()
        self._zstd = zstandard.ZstdDecompressor()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.send(CAMERA)

    # -- receiving ----------------------------------------------------------------------------
    def _read(self) -> None:
        try:
            while True:
                raw = self.ws.recv()
                size = int.from_bytes(raw[:8], "little")
                packed = int.from_bytes(raw[8:16], "little")
                body = self._zstd.decompress(raw[16 : 16 + packed], max_output_size=size)
                with self._cond:
                    for m in msgspec.msgpack.decode(body)["messages"]:
                        self._take(m)
                    self._cond.notify_all()
        except (websockets.exceptions.ConnectionClosed, OSError):
            pass
        finally:
            with self._cond:
                self.closed = True
                self._cond.notify_all()

    def _take(self, m: dict) -> None:
        self.messages += 1
        kind = m["type"]
        if "props" in m and "uuid" in m and kind.startswith("Gui"):
            self.gui[m["uuid"]] = {
                "type": kind,
                **m["props"],
                "value": m.get("value"),
                "container": m.get("container_uuid"),
                "tabs": m.get("tab_container_ids", ()),
            }
        elif kind == "GuiUpdateMessage" and m["uuid"] in self.gui:
            self.gui[m["uuid"]].update(m["updates"])
        elif kind == "GuiRemoveMessage":
            self.gui.pop(m["uuid"], None)
        elif kind == "NotificationShowMessage":
            self.notes.append(f"{m['props']['title']}: {m['props']['body']}")

    # -- reading the page ---------------------------------------------------------------------
    def shown(self, uuid: str) -> bool:
        """Whether the element is visible with every folder around it (as a user sees it)."""
        seen = set()
        while uuid in self.gui and uuid not in seen:
            seen.add(uuid)
            if not self.gui[uuid].get("visible", True):
                return False
            uuid = self.gui[uuid]["container"]
        return True

    def find(self, label: str, kind: str = "", *, shown: bool = True) -> list[str]:
        """uuids of the elements labelled `label` (of message type Gui<kind>Message)."""
        with self._cond:
            return [
                u
                for u, g in self.gui.items()
                if g.get("label") == label
                and (not kind or g["type"] == f"Gui{kind}Message")
                and (not shown or self.shown(u))
            ]

    def one(self, label: str, kind: str = "") -> str:
        found = self.find(label, kind)
        assert len(found) == 1, f"{len(found)} shown elements labelled {label!r}"
        return found[0]

    def value(self, label: str, kind: str = "") -> Any:
        return self.gui[self.one(label, kind)]["value"]

    def text(self) -> str:
        """Every shown markdown's text, in no particular order."""
        with self._cond:
            return "\n".join(
                g.get("_markdown", "")
                for u, g in self.gui.items()
                if g["type"] == "GuiMarkdownMessage" and self.shown(u)
            )

    def enabled(self, label: str) -> bool:
        """A button with this label is shown and can be pressed."""
        with self._cond:
            return any(not self.gui[u].get("disabled") for u in self.find(label, "Button"))

    def wait(self, cond: Callable[[], bool], what: str, timeout_s: float = 600.0) -> None:
        """Until `cond()` holds for what the server has sent; the ceiling only stops a hang."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not cond():
                left = deadline - time.monotonic()
                assert left > 0, f"the page never showed {what}:\n{self.text()}"
                assert not self.closed, f"the server closed the page before {what}"
                self._cond.wait(min(left, 1.0))

    def wait_enabled(self, label: str, timeout_s: float = 600.0) -> str:
        self.wait(lambda: self.enabled(label), f"{label!r} enabled", timeout_s)
        return self.one(label, "Button")

    # -- acting -------------------------------------------------------------------------------
    def send(self, message: dict) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def update(self, uuid: str, **updates: Any) -> None:
        """What the browser sends when a control changes (or anything a forged client may)."""
        self.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": updates})

    def click(self, label: str, timeout_s: float = 1200.0) -> None:
        """Press the button labelled `label` once it is shown and enabled."""
        self.update(self.wait_enabled(label, timeout_s), value=True)

    def click_scene(self, x: float, y: float) -> None:
        """A click in the 3D view at the point (x, y) of its z = 0 plane, where the page's image
        lies (what the browser sends: the ray through the clicked pixel, here straight down)."""
        self.send(
            {
                "type": "ScenePointerMessage",
                "event_type": "click",
                "ray_origin": (float(x), float(y), 20.0),
                "ray_direction": (0.0, 0.0, -1.0),
                "screen_pos": ((0.5, 0.5),),
                "modifier": None,
            }
        )

    def close(self) -> None:
        self.ws.close()
        self._reader.join(timeout=30)


def free_port() -> int:
    """A port on 127.0.0.1 free now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def session_events(folder: Path) -> list[dict]:
    """The events of a page session folder's log, in order."""
    return [json.loads(x) for x in (folder / "session.jsonl").read_text().splitlines()]


def same_page(a: PageWire, b: PageWire) -> None:
    """Until both tabs show the same words and the same task controls."""

    def same() -> bool:
        controls = [(t.value("world"), t.value("shift"), t.value("seed")) for t in (a, b)]
        return a.text() == b.text() and controls[0] == controls[1]

    a.wait(same, "the same page in both tabs", CEILING_S)
