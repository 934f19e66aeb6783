"""`dfa run --world W` starts from the finetuning settings W declares (World.adapting), shows
them in its --help, and lets every option given on the command line win."""

from dataclasses import fields

import pytest

from dfa_viz.cli import main, named_world, parse
from dfa_viz.configs import AdaptConfig, Finetuning
from sim import get_world
from sim.core import Adapting

PICK = "fetch:FetchPickAndPlace-v4"


def test_every_setting_a_world_declares_is_an_option():
    options = {f.name for f in fields(AdaptConfig)} | {f.name for f in fields(Finetuning)}
    assert {f.name for f in fields(Adapting)} <= options


def test_a_world_that_declares_settings_runs_with_them():
    world = get_world(PICK)
    declared = {f.name: getattr(world.adapting, f.name) for f in fields(Adapting)}
    assert any(v is not None for v in declared.values())
    adapt = parse(["run", "--world", PICK]).adapt
    assert adapt == AdaptConfig.for_world(world) != AdaptConfig()
    assert adapt.check(world) is adapt  # settings the world can run
    paper = AdaptConfig()
    for name, value in declared.items():
        on, was = (adapt, paper) if name == "budget" else (adapt.finetuning, paper.finetuning)
        assert getattr(on, name) == (getattr(was, name) if value is None else value)
    assert adapt.finetuning.n_eval == paper.finetuning.n_eval  # not declared: the paper's
    assert parse(["run", f"--world={PICK}", "--seed", "3"]).adapt == adapt


def test_options_given_win_over_the_world_s():
    args = parse(
        ["run", "--world", PICK, "--budget", "25", "--dagger-rounds", "0", "--n-eval", "30"]
    )
    world = get_world(PICK).adapting
    assert (args.adapt.budget, args.adapt.finetuning.dagger_rounds) == (25, 0)
    assert args.adapt.finetuning.n_eval == 30
    assert args.adapt.finetuning.replay_looks == world.replay_looks  # not given: the world's
    assert args.adapt.finetuning.steps == world.steps


@pytest.mark.parametrize("name", ["nav2d", "fetch:FetchPush-v4"])
def test_other_worlds_keep_the_paper_s_settings(name):
    assert get_world(name).adapting == Adapting()
    assert parse(["run", "--world", name]).adapt == AdaptConfig()
    assert parse(["run"]).adapt == AdaptConfig()


def test_help_shows_the_world_s_settings(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", "--world", PICK, "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    budget = text.split("--budget INT", 1)[1].split("--", 1)[0]
    assert f"(default: {get_world(PICK).adapting.budget})" in budget


def test_the_last_world_given_counts():
    assert named_world(["--world", "nav2d", "--world=doorkey"]) == "doorkey"
    assert named_world(["--seed", "1", "--world"]) is None


def test_an_unknown_world_is_one_line(capsys):
    assert main(["run", "--world", "nowhere", "--budget", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown world 'nowhere'" in err[0]
