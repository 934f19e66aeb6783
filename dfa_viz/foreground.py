"""A server in the foreground: wait until Ctrl-C or SIGTERM, then stop it and say so. Used by
`dfa serve`, `dfa demo` and `dfa study serve`."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable


class _Terminated(Exception):
    """SIGTERM arrived (a service manager, `kill`): stop as for Ctrl-C."""


def _terminate(_signum, _frame) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends the process at once
    raise _Terminated()


def wait_then_stop(stop: Callable[[], None], *, stopped: str) -> None:
    """Block until Ctrl-C or SIGTERM (SIGTERM is caught only on the main thread, and its
    previous handler put back), then call `stop()` and print `stopped`."""
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main else None
    try:
        while True:
            time.sleep(3600)
    except (KeyboardInterrupt, _Terminated):
        pass
    finally:
        try:
            stop()
        finally:
            if main and previous is not None:
                signal.signal(signal.SIGTERM, previous)
        print(stopped, flush=True)
