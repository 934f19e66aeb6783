"""The learning-rate schedule of a fit (TrainConfig.lr_schedule, World.cloning's): constant,
as every committed policy was trained, or a half cosine down to 0."""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from policy.base import recipe
from policy.train import TrainConfig, behaviour_clone, learning_rate, training_demos
from sim.core import UserError

COSINE = TrainConfig(steps=100, lr=1e-3, lr_schedule="cosine")


def test_a_cosine_schedule_falls_from_the_rate_to_nothing_and_a_constant_one_stays():
    assert learning_rate(COSINE, 0) == 1e-3
    assert learning_rate(COSINE, 50) == pytest.approx(0.5e-3)
    assert learning_rate(COSINE, 99) < 1e-6
    rates = [learning_rate(COSINE, s) for s in range(100)]
    assert all(a > b for a, b in itertools.pairwise(rates))
    assert {learning_rate(TrainConfig(steps=100), s) for s in range(100)} == {1e-3}


def test_the_recipe_names_a_schedule_only_where_it_is_not_constant(nav):
    demos = training_demos(nav)[:2]
    plain = recipe(nav, demos, seed=0, config=TrainConfig())
    assert "lr_schedule" not in plain["train"]  # the committed policies' recipes read the same
    assert recipe(nav, demos, seed=0, config=COSINE)["train"]["lr_schedule"] == "cosine"


def test_an_unknown_schedule_is_one_line_before_any_training(nav):
    demos = training_demos(nav)[:1]
    config = dataclasses.replace(COSINE, lr_schedule="step")
    with pytest.raises(UserError, match="'step' is not known; accepted: constant, cosine"):
        behaviour_clone(nav, demos, config=config)
