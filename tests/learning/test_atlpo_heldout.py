"""The held-out-teammate protocol (issue 15 item 8): the split, a user's ``module:callable`` team, seeded
episodes, and scores normalised between random (0) and the original teammate (1)."""

import sys
import types

import numpy as np
import pytest
import torch

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.stats import summarise_sample
from embodied_adhoc.learning.atlpo import load_library, shipped_library
from embodied_adhoc.learning.atlpo_heldout import AGENTS, evaluate_held_out, held_out_teams, normalised_scores

torch.set_num_threads(1)


@pytest.fixture
def user_module(monkeypatch):
    module = types.ModuleType("heldout_user_team")
    module.stay = lambda rules, state, task, rng, members: np.full(len(members), 4)
    module.broken = lambda rules, state, task, rng, members: np.full(len(members) + 1, 9)
    module.not_callable = 3
    monkeypatch.setitem(sys.modules, "heldout_user_team", module)
    return module


def test_the_split_and_a_users_team(user_module):
    names = [team.name for team in held_out_teams("pursuit", "heldout_user_team:stay")]
    assert names[:3] == ["tau0+noise0.2", "tau1+noise0.2", "tau2+noise0.2"]
    assert any(name.startswith("mixed-") for name in names) and names[-1] == "heldout_user_team:stay"
    for reference, message in (
        ("heldout_user_team", "module:callable"),
        ("no_such_module_xyz:f", "cannot import"),
        ("heldout_user_team:missing", "cannot import"),
        ("heldout_user_team:not_callable", "not callable"),
    ):
        with pytest.raises(ConfigError, match=message):
            held_out_teams("foraging", reference)


def test_episodes_are_seeded_and_a_bad_team_is_refused(user_module):
    library, classifier = load_library(shipped_library("foraging"))
    teams = held_out_teams("foraging", "heldout_user_team:stay")
    chosen = (teams[3], teams[-1])  # a mixed team and the user's (teammates that never move: nobody forages)
    first = evaluate_held_out(library, classifier, chosen, episodes=2, seed=5, max_steps=15)
    assert first == evaluate_held_out(library, classifier, chosen, episodes=2, seed=5, max_steps=15)
    assert set(first) == {chosen[0].name, chosen[1].name} and set(first[chosen[0].name]) == set(AGENTS)
    assert first[chosen[1].name]["original"]["steps"] == [15, 15] and not any(
        first[chosen[1].name]["atlpo-mf"]["finished"]
    )
    broken = held_out_teams("foraging", "heldout_user_team:broken")[-1]
    with pytest.raises(ConfigError, match="one action in 0..4 per listed member"):
        evaluate_held_out(library, classifier, (broken,), episodes=1, seed=0, max_steps=3)


def test_scores_are_normalised_between_random_and_the_original_teammate():
    def cell(original, known, atlpo, random):
        return {
            "team": {
                name: {"steps": steps, "finished": [True] * len(steps)}
                for name, steps in zip(AGENTS, (original, known, atlpo, random), strict=True)
            }
        }

    scores = normalised_scores(
        [cell([10, 10], [10, 10], [55, 55], [100, 100]), cell([10, 10], [100, 100], [55, 55], [100, 100])],
        summarise_sample,
    )
    assert scores["team"]["episodes"] == 4
    assert (
        scores["team"]["atlpo-mf"]["iqm"] == pytest.approx(0.5) and scores["team"]["atlpo-mf"]["mean"] == 0.5
    )
    assert scores["team"]["known-task"]["mean"] == pytest.approx(
        0.5
    )  # two at 1 (the original), two at 0 (random)
    useless = normalised_scores(
        [cell([100], [10], [10], [100])], summarise_sample
    )  # the team is no better than random: no scale
    assert np.isnan(useless["team"]["atlpo-mf"]["iqm"])
