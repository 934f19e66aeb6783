"""Worlds registered from outside the checkout: register_world never replaces a name, a
"module:Class" name registers the world it names, DFA_WORLDS lists such names, and an
installed package's "dfa.worlds" entry point is found by `dfa worlds` and `dfa check-world`."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import sim
from sim.core import UserError

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "docs" / "examples"
DFA = Path(sys.executable).parent / "dfa"

MODULE = """
from corridor import CorridorWorld


class {cls}(CorridorWorld):
    name = "{name}"
"""


@pytest.fixture
def examples_on_path(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))


def _module(folder: Path, module: str, cls: str, name: str) -> None:
    (folder / f"{module}.py").write_text(MODULE.format(cls=cls, name=name))


def test_a_name_is_never_replaced(examples_on_path):
    sim.register_world("corridor", "corridor:CorridorWorld")
    sim.register_world("corridor", "corridor:CorridorWorld")  # the same again: nothing changes
    with pytest.raises(UserError, match=r"a world named 'nav2d' is already registered") as err:
        sim.register_world("nav2d", "corridor:CorridorWorld")
    assert "\n" not in str(err.value)
    with pytest.raises(UserError, match="already registered"):
        sim.register_world("minigrid", "corridor:CorridorWorld")  # a prefix's name too
    with pytest.raises(UserError, match="no ':'"):
        sim.register_world("a:b", "corridor:CorridorWorld")
    assert type(sim.get_world("nav2d")).__name__ == "Nav2DWorld"


def test_a_module_class_name_registers_its_world(examples_on_path):
    world = sim.get_world("corridor:CorridorWorld")
    assert world.name == "corridor" and sim.get_world("corridor") is world
    assert sim.check_world_name("corridor:CorridorWorld") == "corridor"
    assert sim.check_world_name("nav2d") == "nav2d"
    reacher = sim.get_world("grid_reacher:reacher")  # a function that returns a World
    assert reacher.name == "gridreacher" and "gridreacher" in sim.world_names()


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("nosuch_module:World", "no module 'nosuch_module' on the Python path"),
        ("corridor:NoSuchClass", "module corridor has no NoSuchClass"),
        ("corridor:COLOURS", "names a dict, not a World subclass"),
        ("grid_reacher:set_value", "building the world raised TypeError"),
        ("no-such-world", "unknown world 'no-such-world'; accepted: nav2d"),
    ],
)
def test_bad_outside_worlds_are_one_line(examples_on_path, name, message):
    with pytest.raises(UserError, match=message) as err:
        sim.get_world(name)
    assert "\n" not in str(err.value)


def test_a_world_whose_name_is_taken_is_refused(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.syspath_prepend(str(tmp_path))
    _module(tmp_path, "taken_name", "Impostor", "nav2d")
    with pytest.raises(UserError, match="a world named 'nav2d' is already registered"):
        sim.get_world("taken_name:Impostor")


def test_dfa_worlds_lists_outside_worlds(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.syspath_prepend(str(tmp_path))
    _module(tmp_path, "listed_worlds", "Listed", "listed-corridor")
    monkeypatch.setenv("DFA_WORLDS", "listed_worlds:Listed, grid_reacher:reacher")
    names = sim.world_names()
    assert {"listed-corridor", "gridreacher"} <= set(names)
    assert sim.get_world("listed-corridor").name == "listed-corridor"
    monkeypatch.setenv("DFA_WORLDS", "listed_worlds:Nothing")
    with pytest.raises(UserError, match=r"^DFA_WORLDS: listed_worlds:Nothing: module"):
        sim.world_names()


def _run(args, folder: Path, **env) -> subprocess.CompletedProcess:
    import os

    full = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(EXAMPLES)]), **env}
    return subprocess.run(
        [str(DFA), *args], cwd=folder, env=full, capture_output=True, text=True, timeout=900
    )


def test_an_entry_point_and_dfa_worlds_reach_the_commands(tmp_path):
    """A package declares a world through the "dfa.worlds" entry point (its metadata on the
    path, as pip install leaves it); DFA_WORLDS names another; `dfa worlds` lists both and
    `dfa check-world` passes them; a failing contract exits 1, an unknown world 2."""
    _module(tmp_path, "packaged_worlds", "Packaged", "packaged-corridor")
    info = tmp_path / "packaged_worlds-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: packaged-worlds\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[dfa.worlds]\npackaged-corridor = packaged_worlds:Packaged\n"
    )
    (tmp_path / "broken_worlds.py").write_text(
        MODULE.format(cls="Broken", name="broken-corridor")
        + "\n    def render_batch(self, scenes):"
        + "\n        return super().render_batch(scenes)[:, :4]\n"
    )
    listed = _run(["worlds"], tmp_path, DFA_WORLDS="grid_reacher:reacher")
    assert listed.returncode == 0, listed.stderr
    lines = {line.split(":")[0] for line in listed.stdout.splitlines()}
    assert {"packaged-corridor", "gridreacher", "nav2d"} <= lines
    ok = _run(["check-world", "packaged-corridor"], tmp_path)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert ok.stdout.count("PASS") == 7
    assert "packaged-corridor: 7 of 7 parts of the world contract hold" in ok.stdout
    bad = _run(["check-world", "broken_worlds:Broken"], tmp_path)  # from the current folder
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "FAIL  rendering: render_batch gives uint8 (4, 4, 56, 3), expected uint8" in bad.stdout
    assert "PASS  encode/decode and edit round trips" in bad.stdout
    unknown = _run(["check-world", "nowhere:Nothing"], tmp_path)
    assert unknown.returncode == 2 and unknown.stderr.count("\n") == 1, unknown.stderr


def test_the_minimal_world_of_the_docs_keeps_the_contract(tmp_path, monkeypatch):
    """docs/bring-your-own.md's skeleton, as written there, passes every part of the contract."""
    from sim.contract import check_world

    page = (REPO / "docs" / "bring-your-own.md").read_text()
    code = page.split("### A minimal world")[1].split("```python")[1].split("```")[0]
    (tmp_path / "docs_lamp.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    world = sim.get_world("docs_lamp:Lamp")
    assert world.name == "lamp"
    assert [r for r in check_world(world) if not r.passed] == []
