"""`dfa serve --demos DIR`: the demonstrate step offers the episodes of a LeRobotDataset that start
from the task's scene (every episode of a dataset that names no scenes), checks and replays the
chosen one as `dfa run --demo lerobot:` does, saves it into the session and searches with it; a
value the page never offered, an episode that fails or is not the task's, and a bad folder are
each refused in one line, and nothing is written for them.

The dataset is made here by `dfa run --lerobot` on nav2d; the tabs are PageWire clients
(page_wire.py). Every wait is for what the page shows; its ceiling only ends a hang.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from page_wire import CEILING_S, PageWire, free_port, session_events

from dfa_viz.app.episodes import DemoEpisodes
from dfa_viz.app.picker import USE_EPISODE
from dfa_viz.cli import main
from dfa_viz.configs import AdaptConfig, Finetuning
from sim.core import UserError
from sim.lerobot import Dataset, Episode, write_dataset
from sim.lerobot.demo import SCENE

pytestmark = pytest.mark.slow
TINY = ["--budget", "3", "--steps", "10", "--n-eval", "2", "--max-size", "1"]
QUICK = AdaptConfig(budget=3, finetuning=Finetuning(steps=10, n_eval=2))
# the run's dataset, in `dfa run --lerobot`'s order: the demonstration, 2 variants, the
# counterfactuals, the failed rollout, the finetuned one; the task's own scene starts these
STARTS_HERE = ("demonstration", "failed", "finetuned")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """nav2d object_ti seed 0 run by `dfa run --lerobot` with small settings."""
    tmp = tmp_path_factory.mktemp("demos")
    code = main(
        ["run", "--world", "nav2d", "--shift", "object_ti", "--seed", "0", *TINY,
         "--out", str(tmp / "rec"), "--lerobot", str(tmp / "ds")]
    )  # fmt: skip
    assert code == 0
    return tmp / "ds"


@pytest.fixture
def served(tmp_path):
    """serve(demos) -> the page served in this process on a new session (stopped after)."""
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    apps = []

    def make(demos: Path | None, session: Path | None = None):
        state = open_state(
            session=session or tmp_path / "s",
            out=tmp_path / "rec",
            adapt=QUICK,
            demos=None if demos is None else DemoEpisodes(demos),
        )
        app = start(port=free_port(), state=state)
        apps.append(app)
        return app

    yield make
    for app in apps:
        app.stop()


def _object_ti(app, tab: PageWire) -> None:
    """Load nav2d object_ti seed 0 (the dataset's task), as the tab's shift dropdown does."""
    tab.wait_enabled("Load task", CEILING_S)
    tab.update(tab.one("shift", "Dropdown"), value="object_ti")
    tab.wait(
        lambda: any(p.task.shift.value == "object_ti" for p in app.pages.values()),
        "the shift taken",
        CEILING_S,
    )
    tab.click("Load task")


def _to_demonstrate(app, tab: PageWire) -> None:
    """Load nav2d object_ti seed 0 and judge it failed."""
    _object_ti(app, tab)
    tab.click("Failed")
    tab.wait(lambda: tab.find("dataset episode", "Dropdown"), "the episode picker", CEILING_S)


def _choose(app, tab: PageWire, label: str) -> None:
    """Choose an episode in the tab's dropdown, as the browser does; until the page took it."""
    tab.update(tab.one("dataset episode", "Dropdown"), value=label)
    tab.wait(
        lambda: any(p.picker.episode.value == label for p in app.pages.values()),
        f"{label} chosen",
        CEILING_S,
    )


def test_the_tasks_episodes_are_offered_and_the_chosen_one_is_replayed_and_saved(
    dataset, served, tmp_path
):
    from dfa_viz.app.server import open_state

    roles = [Dataset(dataset).episode(i).text("dfa.role") for i in range(len(Dataset(dataset)))]
    app = served(dataset)
    folder = app.state.session.folder
    tab = PageWire(app.url)
    try:
        tab.wait_enabled("Load task", CEILING_S)
        assert not tab.find("dataset episode") and not tab.find(USE_EPISODE)  # no task yet
        _to_demonstrate(app, tab)
        uuid = tab.one("dataset episode", "Dropdown")
        offered = tuple(tab.gui[uuid]["options"])
        want = [i for i, r in enumerate(roles) if r in STARTS_HERE]
        assert [int(o.split()[1]) for o in offered] == want
        assert [o.split(" · ")[1] for o in offered] == list(STARTS_HERE)
        assert offered[0] == "episode 0 · demonstration · succeeds · 20 steps"
        assert "fails" in offered[1]  # the failed rollout says so
        assert f"3 of the {len(roles)} episodes of `ds` start from this task's scene." in tab.text()

        # a value the page never offered: refused in one line, on that tab, never taken
        for value in ("episode 1 · variant · succeeds · 20 steps", "episode 99", "../../etc"):
            n = len(tab.notes)
            tab.update(uuid, value=value)
            tab.wait(lambda n=n: len(tab.notes) > n, f"the refusal of {value!r}", CEILING_S)
            assert (
                tab.notes[-1].startswith("Refused: dataset episode ")
                and "\n" not in (tab.notes[-1])
            )
            assert tab.gui[uuid]["value"] == offered[0]
        # and the state refuses what the page does not offer for this task, whoever asks
        log = (folder / "session.jsonl").read_bytes()
        for episode in (1, 99, -1, True, "0"):
            with pytest.raises(UserError, match="is not offered for this task; offered: 0, 4, 5"):
                app.state.demonstrate(episode=episode)
        # an offered episode that does not succeed: one line on the page, nothing written
        _choose(app, tab, offered[1])
        tab.click(USE_EPISODE)
        tab.wait(lambda: "**Error:**" in tab.text(), "the refusal of a failed episode", CEILING_S)
        (line,) = [x for x in tab.text().splitlines() if "**Error:**" in x]
        assert f"the {dataset} episode 4 demonstration does not succeed" in line
        assert (folder / "session.jsonl").read_bytes() == log

        _choose(app, tab, offered[0])
        tab.click(USE_EPISODE)
        tab.wait(lambda: "Counterfactual found" in tab.text(), "the counterfactual", CEILING_S)
    finally:
        tab.close()
    record = app.state.record
    ep = Dataset(dataset).episode(0)
    assert np.array_equal(record.demo.actions, ep.actions)
    assert np.array_equal(record.demo.observations[: ep.length], ep.frames)  # the replay's
    assert record.demo_source == f"{dataset} episode 0"
    assert str(record.edit).startswith("goal.shape: square")  # the planted cause
    (demo,) = [e for e in session_events(folder) if e["type"] == "demonstration"]
    assert demo["source"] == f"{dataset} episode 0"
    assert (folder / demo["file"]).is_file()

    # resumed without --demos: the demonstration and its diagnosis are the session's own
    app.stop()
    again = open_state(session=folder, out=tmp_path / "rec")
    try:
        assert again.record.stage == "feedback"
        assert again.record.demo_source == record.demo_source
        assert np.array_equal(again.record.demo.observations, record.demo.observations)
        assert again.record.edit == record.edit
    finally:
        again.close()


def test_a_dataset_without_scenes_offers_every_episode_and_refuses_another_tasks(
    dataset, served, tmp_path
):
    """Anyone's dataset names no scenes: every episode is offered, and the chosen one's frames
    must be the replay's from the task's scene; the first that differs is named in one line."""
    from dfa_viz.app.server import wait_idle

    ds = Dataset(dataset)
    demo, other = ds.episode(0), ds.episode(3)  # the demonstration, a counterfactual
    assert other.text("dfa.role") == "counterfactual"
    actions = demo.actions.copy()
    actions[6] += np.float32(0.6)  # frames 7 on are no longer what these actions show

    def plain(ep: Episode, actions=None) -> Episode:
        columns = {k: v for k, v in ep.columns.items() if k != SCENE}
        return Episode(ep.task, ep.frames, ep.actions if actions is None else actions,
                       ep.success, columns)  # fmt: skip

    root = tmp_path / "theirs"
    episodes = [plain(demo), plain(demo, actions), plain(other)]
    write_dataset(root, episodes, fps=10, robot_type="nav2d", video=False)
    app = served(root)
    state, folder = app.state, app.state.session.folder
    state.pick("nav2d", "object_ti", 0)
    wait_idle(state, timeout_s=CEILING_S)
    state.judge(True)
    task = state.record.task
    assert [e.index for e in state.demos.offered(task)] == [0, 1, 2]
    assert "names no scenes: all 3 episodes are offered" in state.demos.describe(task)
    log = (folder / "session.jsonl").read_bytes()
    for episode, first in [
        (1, "frame 7 is not what nav2d shows after actions 0 to 6 replayed from the start"),
        (2, "frame 0 is not what nav2d shows after the task's start"),
    ]:
        state.demonstrate(episode=episode)
        with pytest.raises(UserError) as refused:
            wait_idle(state, timeout_s=CEILING_S)
        line = str(refused.value)
        assert line.startswith(f"{root} episode {episode}: {first} (") and "\n" not in line
        assert line == state.jobs.error  # what the page shows
        assert (folder / "session.jsonl").read_bytes() == log and state.record.stage == (
            "demonstrate"
        )
    state.demonstrate(episode=0)
    wait_idle(state, timeout_s=CEILING_S)
    assert state.record.stage == "feedback" and state.record.demo_source == f"{root} episode 0"


def test_without_demos_the_page_offers_no_episode(served):
    from dfa_viz.app.server import wait_idle

    app = served(None)
    tab = PageWire(app.url)
    try:
        _object_ti(app, tab)
        tab.click("Failed")
        tab.wait(lambda: tab.enabled("Ask the expert"), "the demonstrate step", CEILING_S)
        assert not tab.find("dataset episode") and not tab.find(USE_EPISODE)
        n = len(tab.notes)
        (uuid,) = tab.find("dataset episode", "Dropdown", shown=False)
        tab.update(uuid, value="episode 0")
        tab.wait(lambda: len(tab.notes) > n, "the refusal", CEILING_S)
        note = tab.notes[-1]
        assert note.startswith("Refused: dataset episode 'episode 0' was not offered")
    finally:
        tab.close()
    wait_idle(app.state, timeout_s=CEILING_S)
    with pytest.raises(UserError, match="no dataset to take an episode from"):
        app.state.demonstrate(episode=0)
    assert app.state.record.stage == "demonstrate"


@pytest.mark.parametrize(
    ("make", "why"),
    [
        (lambda tmp: tmp / "missing", "not a LeRobot dataset (no such folder)"),
        (lambda tmp: tmp / "empty", "not a LeRobot dataset (no meta/info.json)"),
    ],
    ids=["missing", "not-a-dataset"],
)
def test_a_bad_demos_folder_is_one_line_before_serving(tmp_path, make, why):
    bad = make(tmp_path)
    if bad.name == "empty":
        bad.mkdir()
    before = sorted(tmp_path.rglob("*"))
    proc = subprocess.run(
        [sys.executable, "-m", "dfa_viz.cli", "serve", "--demos", str(bad), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=600,  # a ceiling for a hung command, not an expectation
        cwd=tmp_path,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.splitlines() == [f"dfa: error: {bad}: {why}"]
    assert "the page is at" not in proc.stdout  # never served
    assert sorted(tmp_path.rglob("*")) == before  # no recordings/, no session folder


def test_dfa_serve_demos_offers_the_datasets_episodes(dataset, tmp_path):
    """The command itself: `dfa serve --session S --demos DIR` reads the dataset before it
    serves, and its page offers the episodes of the session's task (loaded and judged here
    first); SIGTERM stops it in one line."""
    from dfa_viz.app.server import open_state, wait_idle

    state = open_state(session=tmp_path / "s", out=tmp_path / "rec", adapt=QUICK)
    try:
        state.pick("nav2d", "object_ti", 0)
        wait_idle(state, timeout_s=CEILING_S)
        state.judge(True)
    finally:
        state.close()
    proc = subprocess.Popen(
        [sys.executable, "-m", "dfa_viz.cli", "serve", "--session", str(tmp_path / "s"),
         "--demos", str(dataset), "--port", "0", "--out", str(tmp_path / "rec")],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    lines = []
    try:
        for line in proc.stdout:  # until the URL (the child ending first ends the loop)
            lines.append(line)
            if "the page is at " in line:
                break
        url = lines[-1].rsplit(" ", 1)[1].strip()
        assert url.startswith("http://127.0.0.1:"), "".join(lines)
        tab = PageWire(url)
        try:
            tab.wait(lambda: tab.find("dataset episode", "Dropdown"), "the picker", CEILING_S)
            options = tab.gui[tab.one("dataset episode", "Dropdown")]["options"]
            assert [o.split(" · ")[:2] for o in options] == [
                ["episode 0", "demonstration"],
                ["episode 4", "failed"],
                ["episode 5", "finetuned"],
            ]
            assert tab.enabled(USE_EPISODE)
        finally:
            tab.close()
    finally:
        proc.terminate()
        out, _ = proc.communicate(timeout=600)  # a ceiling for a hung server only
    assert proc.returncode == 0, "".join(lines) + out
    assert "Traceback" not in "".join(lines) + out
    assert "dfa serve: stopped; the session is saved in" in out
