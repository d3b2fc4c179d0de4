"""The chapter-5 domains beyond pursuit-task and gridworld: every member a deterministic policy of the right shape,
the families' definitions per domain (the teammate's own stay action, the next task on the same states, mixed
teams), and the per-agent comparison of two backends (the bounds on these domains: test_bench_bounds)."""

import numpy as np
import pytest

from embodied_adhoc.bench.evaluate import backend_difference
from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.stats import welch_test
from embodied_adhoc.teammates.chapter5_members import Chapter5MemberFactory, other_task
from embodied_adhoc.teammates.populations import CHAPTER5, find_member, members, population

NEW_DOMAINS = tuple(d for d in CHAPTER5 if d not in ("pursuit-task", "gridworld"))


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def libraries():
    built = {}

    def get(domain):
        if domain not in built:
            built[domain] = build_library(domain)
        return built[domain]

    return get


@pytest.mark.parametrize("domain", NEW_DOMAINS)
def test_every_member_is_a_deterministic_policy_of_each_model(domain, libraries):
    library = libraries(domain)
    models = library.native_pomdps or library.pomdps
    for spec in population(domain):
        for m in (0, library.n_models - 1):  # the first and last model: each family's shape and rows
            policy = spec.factory()(library, m)
            n_teammate = library.mmdps[m].n_actions // library.n_actions
            assert policy.shape == (models[m].n_states, n_teammate)
            assert policy.min() >= 0.0 and np.allclose(policy.sum(axis=1), 1.0)
        assert np.array_equal(policy, spec.factory()(library, library.n_models - 1))
    assert members(domain, "held-out") and members(domain, "validation") and members(domain, "train")


@pytest.mark.parametrize(("domain", "stay"), [("pursuit-teammate", 4), ("overcooked", 2), ("power-plant", 3)])
def test_lazy_member_adds_the_teammates_own_stay(domain, stay, libraries):
    library = libraries(domain)
    base = Chapter5MemberFactory("base", {"family": "epsilon", "epsilon": 0.0})(library, 0)
    lazy = find_member(domain, "lazy-p60").factory()(library, 0)
    extra = lazy - 0.4 * base
    assert np.allclose(extra[:, stay], 0.6)
    assert np.allclose(np.delete(extra, stay, axis=1), 0.0)


def test_goal_switching_needs_another_task_on_the_same_states(libraries):
    both = libraries("pursuit-both")
    for m in range(both.n_models):
        k = other_task(both, m)
        assert (
            both.task_names[k].split(":")[1] != both.task_names[m].split(":")[1]
        )  # another capture, any mate
    for domain in ("pursuit-teammate", "power-plant", "overcooked"):
        library = libraries(domain)
        assert other_task(library, 0) is None
        assert not any(s.params["family"] == "goal-mix" for s in population(domain))
        with pytest.raises(ConfigError, match="needs another task on the same states"):
            Chapter5MemberFactory("x", {"family": "goal-mix", "other": 1.0})(library, 0)


def test_mixed_team_is_the_weighted_average_of_the_librarys_teammates(libraries):
    library = libraries("pursuit-teammate")
    mixed = find_member("pursuit-teammate", "mix-greedy-aware").factory()(library, 1)
    expected = 0.5 * library.teammates["greedy"](1) + 0.5 * library.teammates["aware"](1)
    assert np.allclose(mixed, expected)
    assert not np.allclose(mixed, library.teammates["greedy"](1))


def test_backend_difference_is_welchs_test_per_agent_and_member():
    rng = np.random.default_rng(0)
    first = {"a": rng.normal(0.8, 0.1, (8, 2)), "b": rng.normal(0.5, 0.2, (8, 2))}
    second = {"a": rng.normal(0.6, 0.1, (6, 2)), "c": rng.normal(0.1, 0.1, (6, 2))}
    result = backend_difference(first, second, ["m0", "m1"])
    assert set(result["agents"]) == {"a"}  # only agents both sides ran
    pooled = result["agents"]["a"]
    t, p = welch_test(second["a"].ravel(), first["a"].ravel())  # t of second - first
    assert (pooled["t"], pooled["p"]) == (t, p)
    assert pooled["difference"] == pytest.approx(second["a"].mean() - first["a"].mean())
    assert pooled["t"] < 0 < -pooled["difference"]  # the second side scores lower here
    assert pooled["n"] == [16, 12]
    t1, p1 = welch_test(second["a"][:, 1], first["a"][:, 1])
    assert (
        result["agents"]["a"]["per_member"]["m1"]["t"],
        result["agents"]["a"]["per_member"]["m1"]["p"],
    ) == (
        t1,
        p1,
    )
    assert "Welch" in result["method"]


@pytest.mark.parametrize("domain", ("power-plant", "pursuit-teammate", "overcooked", "ntu"))
def test_the_best_response_bounds_the_state_observing_agent_exactly(domain):
    """``value-iteration`` (greedy on the library's Q*, ties uniform) evaluated exactly in each held-out member's
    world over the trial cap: at most the best response's value from every state (no CI needed: both exact)."""
    from embodied_adhoc.bench.bounds import member_bounds, world_mdps
    from embodied_adhoc.bench.evaluate import domain_defaults
    from embodied_adhoc.experiments.registry import get_trial_domain

    options, horizon = domain_defaults(domain)
    session = get_trial_domain(domain).open_session("abstract", options)
    q_library = session.q_values()
    for spec in members(domain, "held-out"):
        bounds = member_bounds(spec, session.library, horizon)
        mdps, _ = world_mdps(spec, session.library)
        for m, mdp in enumerate(mdps):
            q = q_library[m]
            best = q.max(axis=1, keepdims=True)
            ties = q >= best - 1e-9 * np.maximum(1.0, np.abs(best))  # selection.pick_best's ties
            policy = ties / ties.sum(axis=1, keepdims=True)
            values = np.zeros(mdp.n_states)
            for _ in range(horizon):
                values = (policy * (mdp.rewards + mdp.expected_next_values(values))).sum(axis=1)
            assert np.all(values <= bounds.best_values[m] + 1e-9), (spec.name, m)
