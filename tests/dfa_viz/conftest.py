"""Fixtures the page's fault and forgery tests share."""

from __future__ import annotations

import pytest
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
