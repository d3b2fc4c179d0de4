"""The grid arenas' benchmark populations (level-based foraging, predator-prey): members deterministic per seed
(scripted and learned), the ATLPO split's held-out teams reproduced draw for draw, the sticky family's memory,
predator-prey's scripted member unlike every thesis team, simulated bounds that normalise random to 0 and the
original team to 1 by construction, and a tiny evaluate that gives the same numbers twice and after resuming."""

import json

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the env ids)
from embodied_adhoc.bench.bounds import ORIGINAL, TRAINED, grid_return, normalise, simulated_bounds
from embodied_adhoc.bench.evaluate import Suite, evaluate
from embodied_adhoc.domains.grid_rules import GridConfig, GridRules
from embodied_adhoc.domains.grid_rules_team import TeamSpec, team_actions
from embodied_adhoc.learning.atlpo_heldout import MIXED, NOISE, thesis_team
from embodied_adhoc.learning.vector_grid import GRID_IDS
from embodied_adhoc.teammates.foraging_teams import FORAGING_TEAMS
from embodied_adhoc.teammates.grid_members import SeatTeam, StickyTeam
from embodied_adhoc.teammates.populations import GRID, SUITE_VERSION, find_member, members, population
from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS

FORAGING_ID = GRID_IDS["foraging"]
EVERY_MEMBER = [spec for domain in GRID for spec in population(domain)]


def _episode(spec, seed: int, steps: int = 25, env=None) -> list:
    own = env is None
    env = env or gymnasium.make(GRID_IDS[spec.domain], teams=[spec.plugin], disable_env_checker=True)
    rng = np.random.default_rng(seed)
    observation, info = env.reset(seed=seed)
    trace = [info["state"]]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = env.step(int(rng.integers(5)))
        trace += [info["state"], reward]
        if terminated or truncated:
            break
    if own:
        env.close()
    return trace


@pytest.mark.parametrize("spec", EVERY_MEMBER, ids=lambda s: f"{s.domain}/{s.name}")
def test_grid_members_are_deterministic_per_seed(spec):
    env = gymnasium.make(GRID_IDS[spec.domain], teams=[spec.plugin], disable_env_checker=True)
    first = _episode(spec, 5, env=env)
    _episode(spec, 6, env=env)  # an episode between: a member's memory starts afresh with each seeded reset
    assert _episode(spec, 5, env=env) == first
    assert _episode(spec, 5) == first  # and a fresh env plays it alike
    env.close()


@pytest.mark.parametrize("domain", GRID)
def test_grid_population_shape(domain):
    held_out = {s.name: s for s in members(domain, "heldout")}
    # the ATLPO split's held-out teams are all held out here
    for tau in ("tau0", "tau1", "tau2"):
        assert held_out[f"{tau}-noise-p20"].params == {"family": "seats", "teams": [tau], "noise": NOISE}
    assert [s.params["teams"] for s in held_out.values() if s.name.startswith("mixed-")] == [
        list(types) for types in MIXED
    ]
    assert [s.name for s in members(domain, "train")] == ["tau0", "tau1", "tau2"]
    learned = [s for s in population(domain) if s.params["family"] == "learned"]
    # foraging's RL teammates of other seeds are for tuning too; predator-prey reuses its shipped agents only
    assert {s.split for s in learned} == (
        {"validation", "held-out"} if domain == "foraging" else {"held-out"}
    )
    for spec in learned:  # named by plug-in spec, weights shipped with the suite
        assert spec.plugin == f"embodied_adhoc.learning.bench_members:{domain}/{spec.name}"
        assert callable(spec.factory())
    assert all(s.version == SUITE_VERSION for s in population(domain))
    assert {s.params["family"] for s in members(domain, "validation")} >= {"seats", "sticky"}


def _pursuit_states(count: int):
    env = gymnasium.make(GRID_IDS["pursuit"], disable_env_checker=True)
    rules = env.unwrapped.core.rules
    for seed in range(count):
        env.reset(seed=seed)
        core = env.unwrapped.core
        yield rules, core.episode.state, core.task
    env.close()


def test_pursuit_teams_differ_by_goal_and_navigation_only():
    """One prey and fixed capture positions: the target and slot rules pick the same cells whatever they are (so a
    ``closest-path`` member would be tau1), and the scripted member, the ring approached greedily, plays unlike
    every thesis team."""
    closest_path = TeamSpec("closest-path", "", target="closest", slot="closest", navigation="path")
    ring_greedy = find_member("pursuit", "ring-greedy")
    assert ring_greedy.params["goal"] == "ring" and ring_greedy.params["navigation"] == "greedy"
    differs = dict.fromkeys(PURSUIT_TEAMS, False)
    for rules, state, task in _pursuit_states(12):
        mine = ring_greedy.factory()(rules)
        for name in ("tau0", "tau1", "tau2"):
            a, b = np.random.default_rng(5), np.random.default_rng(5)
            ours = team_actions(rules, state, task, mine, a, [1, 2, 3])
            differs[name] |= not np.array_equal(
                ours, team_actions(rules, state, task, PURSUIT_TEAMS[name], b, [1, 2, 3])
            )
        a, b = np.random.default_rng(5), np.random.default_rng(5)
        assert np.array_equal(
            team_actions(rules, state, task, closest_path, a, [1, 2, 3]),
            team_actions(rules, state, task, PURSUIT_TEAMS["tau1"], b, [1, 2, 3]),
        )
    assert differs["tau0"] and differs["tau1"] and differs["tau2"]


def _state_and_task(seed: int):
    rules = GridRules(GridConfig(domain="foraging", rows=5, cols=5, n_agents=4))
    env = gymnasium.make(FORAGING_ID, disable_env_checker=True)
    env.reset(seed=seed)
    core = env.unwrapped.core
    state, task = core.episode.state, core.task
    env.close()
    return rules, state, task


@pytest.mark.parametrize("types", [("tau1",), *MIXED], ids=lambda t: "-".join(t))
def test_seat_team_is_the_atlpo_split_draw_for_draw(types):
    rules, state, task = _state_and_task(3)
    noise = NOISE if len(types) == 1 else 0.0
    ours = SeatTeam(rules, tuple(FORAGING_TEAMS[t] for t in types), noise)
    theirs = thesis_team(FORAGING_TEAMS, types, noise)
    for members_ in ([1, 2, 3], [0]):
        a, b = np.random.default_rng(11), np.random.default_rng(11)
        for _ in range(20):
            assert np.array_equal(
                ours.actions(state, task, a, members_), theirs(rules, state, task, b, members_)
            )


def test_sticky_member_repeats_its_own_action():
    rules, state, task = _state_and_task(4)
    always = StickyTeam(rules, FORAGING_TEAMS["tau2"], 1.0)
    rng = np.random.default_rng(0)
    first = always.actions(state, task, rng, [1, 2, 3])
    for _ in range(5):
        assert np.array_equal(always.actions(state, task, rng, [1, 2, 3]), first)
    never = StickyTeam(rules, FORAGING_TEAMS["tau2"], 0.0)
    a, b = np.random.default_rng(1), np.random.default_rng(1)
    from embodied_adhoc.domains.grid_rules_team import team_actions

    for _ in range(5):  # p = 0: the thesis team itself
        expected = team_actions(rules, state, task, FORAGING_TEAMS["tau2"], b, [1, 2, 3])
        b.random(3)
        assert np.array_equal(never.actions(state, task, a, [1, 2, 3]), expected)


def _options(spec) -> dict:
    from embodied_adhoc.bench.evaluate import domain_defaults

    options, max_steps = domain_defaults(spec.domain)
    return {**spec.trial_options(options), "bench_member": spec.describe()}, max_steps


@pytest.mark.parametrize("domain", GRID)
def test_simulated_bounds_normalise_random_to_0_and_the_original_team_to_1(tmp_path, domain):
    spec = find_member(domain, "tau1-noise-p20")
    options, max_steps = _options(spec)
    # the original team alone (the trained best response's side: tests/bench/test_bench_best_response.py)
    bounds = simulated_bounds(domain, options, max_steps, tmp_path / "a", episodes=3, seed=2, trained=False)
    again = simulated_bounds(domain, options, max_steps, tmp_path / "b", episodes=3, seed=2, trained=False)
    assert (bounds.random, bounds.best) == (again.random, again.best)
    assert bounds.upper == ORIGINAL and bounds.episodes == 3
    assert -max_steps <= bounds.random < bounds.best < 0
    assert normalise(bounds.random, bounds) == 0.0
    assert normalise(bounds.best, bounds) == 1.0
    with pytest.raises(Exception, match="exact bound"):
        bounds.on_starts([(0, 0)])


def test_grid_return_is_minus_the_steps():
    class Record:
        steps, total_reward = 17, 1.0

    assert grid_return(Record()) == -17.0


@pytest.mark.parametrize("domain", GRID)
def test_tiny_grid_evaluate_gives_the_same_numbers_twice_and_after_resuming(tmp_path, domain):
    specs = (find_member(domain, "sticky-tau2-p50"), find_member(domain, "tau0-noise-p20"))
    suite = Suite("heldout", SUITE_VERSION, {domain: specs})

    def run(out):
        return evaluate(
            ("random", "ppo-generalist"), suite, out, episodes=2, bound_episodes=2, plots=False, reps=50
        )

    first = run(tmp_path / "one")
    second = run(tmp_path / "two")
    resumed = run(tmp_path / "one")  # every trial stored: read back, not run again
    assert json.dumps(first, sort_keys=True) == json.dumps(second, sort_keys=True)
    assert json.dumps(first, sort_keys=True) == json.dumps(resumed, sort_keys=True)
    rows = first["domains"][domain]["teammates"]
    assert [row["name"] for row in rows] == ["sticky-tau2-p50", "tau0-noise-p20"]
    for row in rows:
        assert row["bounds"]["upper"] in (ORIGINAL, TRAINED) and row["best_on_episodes"] is None
        assert row["bounds"]["random"] < row["bounds"]["best"]
        # both candidates are written, and the bound is the better one, named by its label
        candidates = {ORIGINAL: row["bounds"]["original"], TRAINED: row["bounds"]["trained"]}
        assert row["bounds"]["best"] == max(candidates.values()) == candidates[row["bounds"]["upper"]]
