"""Fixtures the page's fault and forgery tests and the interrupted-writes tests share."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from interrupted import EXPLAIN, PRIOR, Q2, SWEEP, dfa
from page_wire import free_port

from dfa_viz.configs import AdaptConfig, Finetuning


@pytest.fixture
def served(tmp_path):
    """The page served in this process on a new session, with a short finetuning: (app,
    session folder). Modules with a page of their own define their own `served`."""
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    quick = AdaptConfig(budget=5, finetuning=Finetuning(steps=20))
    state = open_state(session=tmp_path / "s", out=tmp_path / "rec", adapt=quick)
    app = start(port=free_port(), state=state)
    yield app, tmp_path / "s"
    app.stop()


@pytest.fixture(scope="session")
def reference(tmp_path_factory) -> Callable[[str], Path]:
    """The output folder of each command run once a test session, uninterrupted (made on
    first use)."""
    made: dict[str, Path] = {}
    commands = {"sweep": SWEEP, "explain": EXPLAIN, "prior": PRIOR, "q2": Q2}

    def get(name: str) -> Path:
        if name not in made:
            out = tmp_path_factory.mktemp(f"reference-{name}")
            target = out / "prior.json" if name == "prior" else out / "out"
            proc = dfa(*commands[name], "--out", str(target))
            assert proc.returncode == 0, proc.stderr[-3000:]
            made[name] = target.parent if name == "prior" else target
        return made[name]

    return get
