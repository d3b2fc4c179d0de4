"""The members' bounds: exact values that simulated episodes reproduce (a random ego; the best response acting on
the true state through the env's privileged channel), normalisation 0/1 by construction, and the content cache."""

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.decision.value_iteration as value_iteration_module
import embodied_adhoc.envs  # noqa: F401  (registers the env ids)
from embodied_adhoc.bench.bounds import Bounds, bounds_cache_dir, member_bounds, normalise, world_mdps
from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.lab import build_lab_library
from embodied_adhoc.envs.library_env import LibraryEnv
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.teammates.populations import TeammateSpec, find_member


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def _q_tables(mdp, horizon: int) -> list[np.ndarray]:
    """``q[t]``: the finite-horizon Q with ``t + 1`` steps to go."""
    values, tables = np.zeros(mdp.n_states), []
    for _ in range(horizon):
        q = mdp.rewards + mdp.expected_next_values(values)
        tables.append(q)
        values = q.max(axis=1)
    return tables


def _run(env, policy, reset_options, seed: int, horizon: int) -> float:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed, options=reset_options)
    total = 0.0
    for step in range(horizon):
        action = policy(getattr(env, "unwrapped", env).privileged_state(), horizon - step - 1, rng)
        _, reward, terminated, _, _ = env.step(action)
        total += reward
        if terminated:
            break
    return total


def _check(returns, expected: float) -> None:
    returns = np.asarray(returns)
    assert abs(returns.mean() - expected) <= 4.0 * returns.std(ddof=1) / np.sqrt(returns.size) + 1e-9


def test_lab_bounds_match_simulated_episodes():
    library, horizon = build_lab_library(), 100
    spec = find_member("toxic-waste", "wander-p40")
    bounds = member_bounds(spec, library, horizon)
    mdps, _ = world_mdps(spec, library)
    tables = [_q_tables(mdp, horizon) for mdp in mdps]
    env = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", human=spec.plugin, disable_env_checker=True)
    n = library.graph.n_nodes
    random_returns, best_returns = [], []
    for episode in range(80):
        draw = np.random.default_rng(episode)
        task = int(draw.integers(library.n_tasks))
        start = {"task": task, "robot_node": int(draw.integers(n)), "human_node": int(draw.integers(n))}
        q = tables[task]
        random_returns.append(
            _run(env, lambda s, t, rng: int(rng.integers(library.n_actions)), start, episode, 100)
        )
        best_returns.append(_run(env, lambda s, t, rng, q=q: int(np.argmax(q[t][s])), start, episode, 100))
    env.close()
    _check(random_returns, bounds.random)
    _check(best_returns, bounds.best)
    assert bounds.best > bounds.random


@pytest.mark.parametrize(
    ("domain", "member", "horizon"),
    [
        ("gridworld", "eps-p50", 50),
        ("power-plant", "softmax-t10", 50),  # a state space of its own per task
        ("overcooked", "mix-upper-lower", 50),  # models that differ in the teammate only
    ],
)
def test_chapter5_bounds_match_simulated_episodes(domain, member, horizon):
    from embodied_adhoc.domains.chapter5.teammates import world_with_teammate

    library = build_library(domain)
    spec = find_member(domain, member)
    bounds = member_bounds(spec, library, horizon)
    mdps, starts = world_mdps(spec, library)
    tables = [_q_tables(mdp, horizon) for mdp in mdps]
    env = LibraryEnv(library, world_with_teammate(library, spec.plugin))
    random_returns, best_returns = [], []
    for episode in range(80):
        draw = np.random.default_rng(episode)
        task = int(draw.integers(library.n_models))
        start = {"task": task, "start": int(library.pomdps[task].sample_initial_state(draw))}
        q = tables[task]
        random_returns.append(
            _run(env, lambda s, t, rng: int(rng.integers(library.n_actions)), start, episode, horizon)
        )
        best_returns.append(
            _run(env, lambda s, t, rng, q=q: int(np.argmax(q[t][s])), start, episode, horizon)
        )
    _check(random_returns, bounds.random)
    _check(best_returns, bounds.best)
    assert np.allclose([s.sum() for s in starts], 1.0)
    assert bounds.best > bounds.random


def test_normalisation_is_zero_for_random_and_one_for_the_best_response():
    bounds = Bounds(random=-160.0, best=-20.0, horizon=100)
    assert normalise([bounds.random, bounds.best, -5.0], bounds) == pytest.approx(
        [0.0, 1.0, 15.0 / 140.0 + 1.0]
    )
    with pytest.raises(ConfigError, match="no better than a random ego"):
        normalise([1.0], Bounds(3.0, 3.0, 10))


def test_bounds_are_cached_by_content(monkeypatch):
    library = build_lab_library()
    spec = find_member("toxic-waste", "slow-p50")
    first = member_bounds(spec, library, 100)
    assert len(list(bounds_cache_dir().glob("*.npz"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("a cached bound was computed again")

    with monkeypatch.context() as patched:
        patched.setattr(value_iteration_module, "value_iteration", refuse)
        assert member_bounds(spec, library, 100) == first
    slower = TeammateSpec("slower", "toxic-waste", "train", "slow", {"slow": 0.6})
    assert member_bounds(slower, library, 100).best < first.best  # another member: another entry
    assert len(list(bounds_cache_dir().glob("*.npz"))) == 2
