"""What every tab of a page session shares besides the loop: the user's quick inputs applied in
the order they arrived, and the tabs told what changed.

Subscribers (the tabs) are called outside the lock with the set of things that changed; one
that raises is reported and the others are still told.
"""

from __future__ import annotations

import itertools
import queue
import threading
import traceback
from collections.abc import Callable

from sim.core import UserError

Listener = Callable[[set[str]], None]


class Hub:
    """Ordered input and subscribers; `self._lock` guards what subclasses keep too."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self.version = 0  # bumps on every notification
        self._listeners: dict[int, Listener] = {}
        self._ids = itertools.count()
        self._inputs: queue.Queue = queue.Queue()
        threading.Thread(target=self._input_loop, name="dfa-inputs", daemon=True).start()

    # -- ordered input: clicks and keys apply in the order they arrived -----------------------
    def submit(self, fn: Callable[[], object], on_error: Callable[[str], None]) -> None:
        """Queue a quick user input (a waypoint, a key); the page calls this from viser's event
        loop, where messages arrive in order (thread-pool callbacks could overtake each other)."""
        self._inputs.put((fn, on_error))

    def stop_inputs(self) -> None:
        self._inputs.put(None)

    def _input_loop(self) -> None:
        while True:
            item = self._inputs.get()
            if item is None:  # closed
                return
            fn, on_error = item
            try:
                fn()
            except UserError as e:
                on_error(str(e))
            except Exception as e:
                traceback.print_exc()
                on_error(f"{type(e).__name__}: {e}")

    # -- subscribers --------------------------------------------------------------------------
    def subscribe(self, fn: Listener) -> Callable[[], None]:
        key = next(self._ids)
        with self._lock:
            self._listeners[key] = fn

        def unsubscribe() -> None:
            with self._lock:
                self._listeners.pop(key, None)

        return unsubscribe

    def _notify(self, what: set[str]) -> None:
        with self._lock:
            self.version += 1
            listeners = list(self._listeners.values())
        for fn in listeners:
            try:
                fn(what)
            except Exception:  # one broken tab must not stop the others
                traceback.print_exc()
