"""Trained best responses on the grid arenas (level-based foraging; each arena ships its own): the vector env hosts
a member's team with the member's own trial draws, a tiny training run is seeded and its weights load from
safetensors, and the simulated upper bound is the better of the trained best response and the original team,
labelled."""

import json

import gymnasium
import numpy as np
import pytest
from safetensors.torch import load_file

import embodied_adhoc.envs  # noqa: F401  (registers the env ids)
from embodied_adhoc.bench.bounds import ORIGINAL, TRAINED, normalise, simulated_bounds
from embodied_adhoc.bench.evaluate import domain_defaults
from embodied_adhoc.experiments.executors import open_session
from embodied_adhoc.experiments.registry import get_trial_domain
from embodied_adhoc.learning.best_response import (
    KIND,
    BestResponseAgentFactory,
    agent_spec,
    shipped_path,
    train_best_response,
    weights_digest,
)
from embodied_adhoc.learning.generalist import GeneralistAgent, load_generalist
from embodied_adhoc.learning.vector_grid import GRID_IDS, GridVectorEnv
from embodied_adhoc.learning.weights import load_weights
from embodied_adhoc.paths import assets_dir
from embodied_adhoc.teammates.populations import GRID, find_member, members

HOSTED = ("tau0-noise-p20", "mixed-tau2-tau0-tau0", "sticky-tau2-p50", "highest-greedy", "ppo-s2")
"""One member of each family: seats (noisy, mixed), sticky, spec (a TeamSpec: the batched planner) and learned."""


def _trial_path(name: str):
    """The member's trial session, options and step cap (the benchmark's own, as ``evaluate`` builds them)."""
    spec = find_member("foraging", name)
    options, max_steps = domain_defaults("foraging")
    options = {**spec.trial_options(options), "bench_member": spec.describe()}
    return spec, options, max_steps, open_session("foraging", "abstract", options)


@pytest.mark.parametrize("name", HOSTED)
def test_the_vector_env_hosts_a_member_with_its_trial_draws(name):
    """A sub-env hosting the member plays the member's trial episode draw for draw: same start (the trial's
    reset options), same teammate actions, observations, rewards and ends, for the same seed and ego actions."""
    spec, options, max_steps, session = _trial_path(name)
    episode_spec = get_trial_domain("foraging").episode_spec(options, np.random.default_rng(11))
    reset_options = session.reset_options(episode_spec)
    trial_env = session.make_env(max_steps)
    hosted = GridVectorEnv(
        "foraging", 1, max_episode_steps=max_steps, teammate_info=True, teams=options["teams"]
    )
    assert hosted.team_names == tuple(trial_env.unwrapped.core.teams)
    actions = np.random.default_rng(3).integers(0, 5, 60)
    for seed in (4, 5):
        observation, info = trial_env.reset(seed=seed, options=reset_options)
        vector_observation, vector_info = hosted.reset(seed=[seed], options=reset_options)
        assert np.array_equal(vector_observation[0], observation)
        assert (
            vector_info["task"][0] == info["task"]
            and hosted.team_names[vector_info["team"][0]] == spec.plugin
        )
        for action in actions.tolist():
            observation, reward, terminated, truncated, info = trial_env.step(action)
            step = hosted.step(np.array([action]))
            assert step[4]["teammate_actions"][0].tolist() == info["teammate_actions"]
            assert np.array_equal(step[0][0], observation)
            assert (step[1][0], step[2][0], step[3][0]) == (reward, terminated, truncated)
            if terminated or truncated:
                break
    trial_env.close()
    hosted.close()


def test_a_policy_member_is_one_object_per_sub_env_and_scripted_envs_draw_as_before():
    """Policy teams get their own object per sub-env (their memories are per episode); a library of scripted teams
    still goes through the batched planner alone (no policy objects)."""
    spec = find_member("foraging", "sticky-tau2-p50")
    hosted = GridVectorEnv("foraging", 3, teams=[spec.plugin])
    objects = [policies[spec.plugin] for policies in hosted.team_policies]
    assert len({id(team) for team in objects}) == 3
    assert hosted.policy_team.tolist() == [name == spec.plugin for name in hosted.team_names]
    scripted = GridVectorEnv("foraging", 3)
    assert not scripted.policy_team.any() and scripted.team_policies == [{}, {}, {}]
    hosted.close()
    scripted.close()


def _tiny(out, seed=0):
    return train_best_response("foraging", "tau1-noise-p10", out, steps=256, envs=4, rollout=32, seed=seed)


def test_a_tiny_best_response_is_seeded_and_loads_from_safetensors(tmp_path):
    report = _tiny(tmp_path / "a")
    assert report["finished"] and report["env_steps"] == 256 and report["cpu_seconds"] > 0
    assert report["settings"]["member"] == "tau1-noise-p10" and report["settings"]["steps"] == 256
    weights = tmp_path / "a" / f"foraging-{KIND}.safetensors"
    tensors = load_file(str(weights))  # safetensors: tensors only, nothing executable
    _, metadata = load_weights(weights)
    assert metadata["kind"] == KIND and metadata["domain"] == "foraging"
    assert metadata["env_kwargs"] == {"teams": [find_member("foraging", "tau1-noise-p10").plugin]}
    assert metadata["warm_start"] == "generalist/foraging/foraging-ppo-generalist.safetensors"
    model, _ = load_generalist(weights, kind=KIND)
    assert isinstance(GeneralistAgent(model), GeneralistAgent)
    with pytest.raises(Exception, match="not a ppo-generalist"):
        load_generalist(weights)  # another kind: not loaded as the generalist
    warm, _ = load_weights(assets_dir() / metadata["warm_start"])
    assert any(not np.array_equal(tensors[k].numpy(), warm[k].numpy()) for k in tensors)  # it trained
    _tiny(tmp_path / "b")
    _tiny(tmp_path / "c", seed=1)
    again, other = (load_file(str(tmp_path / folder / weights.name)) for folder in ("b", "c"))
    assert all(
        np.array_equal(tensors[k].numpy(), again[k].numpy()) for k in tensors
    )  # same seed, same weights
    assert any(not np.array_equal(tensors[k].numpy(), other[k].numpy()) for k in tensors)
    assert json.loads((tmp_path / "a" / "training.json").read_text())["cpu_seconds"] == report["cpu_seconds"]


@pytest.mark.parametrize("split", ("heldout", "validation"))
@pytest.mark.parametrize("domain", GRID)
def test_every_held_out_and_validation_member_ships_a_best_response(domain, split):
    for spec in members(domain, split):
        path = shipped_path(domain, spec.name)
        assert path.is_file(), spec.name
        _, metadata = load_weights(path)
        assert metadata["kind"] == KIND and metadata["env_kwargs"] == {"teams": [spec.plugin]}
        assert metadata["domain"] == domain
        assert metadata["warm_start"] == f"generalist/{domain}/{domain}-ppo-generalist.safetensors"
        report = json.loads((path.parent / "training.json").read_text())
        assert report["finished"] and report["settings"]["member"] == spec.name
        assert report["env_steps"] > 0 and report["cpu_seconds"] > 0


def test_the_upper_bound_is_the_better_of_the_trained_best_response_and_the_original_team(tmp_path):
    spec, options, max_steps, _ = _trial_path("tau0-noise-p20")
    bounds = simulated_bounds("foraging", options, max_steps, tmp_path / "a", episodes=3, seed=2)
    again = simulated_bounds("foraging", options, max_steps, tmp_path / "b", episodes=3, seed=2)
    assert bounds == again and (bounds.original, bounds.trained) == (again.original, again.trained)
    assert bounds.trained is not None and bounds.best == max(bounds.original, bounds.trained)
    assert bounds.upper == (TRAINED if bounds.trained > bounds.original else ORIGINAL)
    assert normalise(bounds.best, bounds) == 1.0 and normalise(bounds.random, bounds) == 0.0
    # the best response's trials are keyed by its weights' bytes
    digest = weights_digest(shipped_path("foraging", spec.name))
    assert (tmp_path / "a" / f"best-response-{digest[:16]}").is_dir()
    original = simulated_bounds(
        "foraging", options, max_steps, tmp_path / "a", episodes=3, seed=2, trained=False
    )
    assert (original.upper, original.best, original.trained) == (ORIGINAL, bounds.original, None)
    assert original.random == bounds.random


def test_the_shipped_best_response_is_an_agent_plug_in():
    spec, options, max_steps, session = _trial_path("highest-greedy")
    from embodied_adhoc.plugins import resolve

    factory = resolve("agent", agent_spec("foraging", spec.name)).factory
    assert isinstance(factory, BestResponseAgentFactory)
    agent = factory(session.agent_library, rng_seed=0)
    assert isinstance(agent, GeneralistAgent)
    missing = BestResponseAgentFactory("foraging", "no-such-member")
    with pytest.raises(Exception, match="no trained best response"):
        missing(session.agent_library)


def test_the_held_out_page_says_per_teammate_which_upper_bound_it_is(monkeypatch):
    import importlib
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "scripts"))
    script = importlib.import_module("bench_heldout")

    def row(name, upper):
        return {
            "name": name,
            "bounds": {"random": -90.0, "best": -12.0, "horizon": 100, "upper": upper, "episodes": 16},
        }

    mixed = {"foraging": {"teammates": [row("a", TRAINED), row("b", ORIGINAL), row("c", TRAINED)]}}
    text = "\n".join(script.simulated_bounds_lines(mixed))
    assert "the better of two mean returns over 16 episodes" in text
    assert "the trained best response for a, c; the original team for b." in text
    assert "not a best response" not in text
    only_original = {"foraging": {"teammates": [row("b", ORIGINAL)]}}
    assert "not a best response" in "\n".join(script.simulated_bounds_lines(only_original))
    assert (
        script.simulated_bounds_lines({"gridworld": {"teammates": [{"name": "x", "bounds": {"best": 1.0}}]}})
        == []
    )


def test_a_policy_team_in_pursuit_draws_the_prey_after_the_team_as_the_single_env(tmp_path):
    """Pursuit's prey draws from the same Generator after the team: a noisy team (a policy object) given by a
    file plug-in plays alike in the vector env and in a SyncVectorEnv of the single env, autoresets included."""
    plugin = tmp_path / "noisy_pursuit.py"
    plugin.write_text(
        "from embodied_adhoc.teammates.grid_members import SeatTeam\n"
        "from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS\n\n\n"
        "def team(rules):\n"
        "    return SeatTeam(rules, (PURSUIT_TEAMS['tau1'], PURSUIT_TEAMS['tau2']), noise=0.3)\n"
    )
    teams = [f"{plugin}:team", "tau0"]
    fast = GridVectorEnv("pursuit", 4, max_episode_steps=15, teams=teams)
    slow = gymnasium.vector.SyncVectorEnv(
        [lambda: gymnasium.make(GRID_IDS["pursuit"], max_episode_steps=15, teams=teams) for _ in range(4)],
        autoreset_mode=gymnasium.vector.AutoresetMode.NEXT_STEP,
    )
    assert fast.policy_team.tolist() == [name == teams[0] for name in fast.team_names]
    observation, info = fast.reset(seed=8)
    assert np.array_equal(observation, slow.reset(seed=8)[0])
    actions, drawn = np.random.default_rng(1), set()
    for _ in range(50):
        chosen = actions.integers(0, 5, 4)
        step, reference = fast.step(chosen), slow.step(chosen)
        for mine, theirs in zip(step[:4], reference[:4], strict=True):
            assert np.array_equal(mine, theirs)
        drawn.update(fast.team_names[t] for t in step[4]["team"])
    assert drawn == set(teams)  # both kinds of team were drawn and played
    fast.close()
    slow.close()


def test_the_shipped_location_and_spec_are_the_trainers_own_names():
    import embodied_adhoc.learning.best_response as trainer
    from embodied_adhoc.learning.generalist import weights_name
    from embodied_adhoc.teammates.best_responses import KIND, TRAINER, shipped_path

    assert TRAINER == trainer.__name__ and trainer.KIND == KIND
    assert shipped_path("pursuit", "x").name == weights_name("pursuit", KIND)
    assert trainer.agent_spec("foraging", "x").split(":")[0] == trainer.__name__
