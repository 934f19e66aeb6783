"""What a tab may set: every control value a tab sends is checked against what the page offered
before the page reads it.

viser takes a control's value from whatever a client sends (a forged message too: a world, a
shift, a label or a number the page never offered, cast to the control's type). `Checked`
keeps the last value the page accepted; a refused value is put back on that tab, which is told
in one line, and nothing acts on it. The page reads `Checked.value`, never the handle's own.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import viser

from sim.core.task import MAX_SEED

SHOWN_CHARS = 60  # of a refused value, in the line the tab is shown


def refuse(client: viser.ClientHandle, text: str) -> None:
    """Tell one tab, in one line, that what it sent was refused."""
    client.add_notification("Refused", text, color="red", auto_close_seconds=8.0)


def refusal(label: str, value: Any, why: str) -> str:
    shown = repr(value)
    if len(shown) > SHOWN_CHARS:
        shown = shown[: SHOWN_CHARS - 1] + "…"
    return f"{label} {shown} was not offered; {why}"


def one_of(options: Callable[[], tuple]) -> Callable[[Any], str]:
    """Allowed: a value among `options()` (read when a value arrives)."""

    def allowed(value: Any) -> str:
        offered = options()
        if value in offered:
            return ""
        listed = ", ".join(map(str, offered[:8])) + (", …" if len(offered) > 8 else "")
        return f"accepted: {listed}"

    return allowed


def whole(low: int | Callable[[], int], high: int | Callable[[], int]) -> Callable[[Any], str]:
    """Allowed: a whole number from low to high (either may be read when a value arrives)."""

    def allowed(value: Any) -> str:
        lo = low() if callable(low) else low
        hi = high() if callable(high) else high
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if ok and value == int(value) and lo <= value <= hi:
            return ""
        return f"accepted: a whole number from {lo} to {hi}"

    return allowed


SEED = whole(0, MAX_SEED)


def hidden(client: viser.ClientHandle, target) -> bool:
    """A press or value from a tab on a control the page does not offer now (hidden or
    disabled): the tab is told so; True when refused."""
    if target.visible and not getattr(target, "disabled", False):
        return False
    label = getattr(target, "label", "") or "that control"
    refuse(client, f"{label} is not offered now")
    return True


class Checked:
    """One control of one tab whose values are checked (`allowed(value)`: "" when offered,
    else what is accepted; nothing while it is hidden). `on_change(event)` runs for every
    accepted change."""

    def __init__(
        self,
        handle,
        allowed: Callable[[Any], str],
        client: viser.ClientHandle,
        on_change: Callable[[Any], None] | None = None,
    ) -> None:
        self.handle, self.client = handle, client
        self._allowed, self._on_change = allowed, on_change
        self._lock = threading.RLock()
        self._value = handle.value
        handle.on_update(self._update)

    @property
    def value(self) -> Any:
        """The last value the page accepted (never a refused one)."""
        return self._value

    def set(self, value: Any) -> None:
        """Show a value of the page's own choosing (e.g. what another tab loaded); on_change
        runs as for a tab's change, with no client."""
        with self._lock:
            changed = value != self._value
            self._value = value
            self.handle.value = value  # viser calls _update at once: nothing to check
        if changed and self._on_change is not None:
            self._on_change(viser.GuiEvent(client=None, client_id=None, target=self.handle))

    def _update(self, event) -> None:
        value = self.handle.value
        with self._lock:
            if value == self._value:
                return  # what was accepted already (or put back)
            if event.client is None:  # the page's own (viser: new options, a value set)
                why = ""
            elif not self.handle.visible:
                why = "it is not shown now"
            else:
                why = self._allowed(value)
            if why:
                self.handle.value = self._value  # the tab shows the accepted value again
            else:
                self._value = value
        if why:
            refuse(self.client, refusal(self.handle.label, value, why))
        elif self._on_change is not None:
            self._on_change(event)
