"""The grid arena's benchmark population (level-based foraging): members deterministic per seed (scripted and
learned), the ATLPO split's held-out teams reproduced draw for draw, the sticky family's memory, simulated bounds
that normalise random to 0 and the original team to 1 by construction, and a tiny evaluate that gives the same
numbers twice and after resuming."""

import json

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the env ids)
from embodied_adhoc.bench.bounds import ORIGINAL, TRAINED, grid_return, normalise, simulated_bounds
from embodied_adhoc.bench.evaluate import Suite, evaluate
from embodied_adhoc.domains.grid_rules import GridConfig, GridRules
from embodied_adhoc.learning.atlpo_heldout import MIXED, NOISE, thesis_team
from embodied_adhoc.teammates.foraging_teams import FORAGING_TEAMS
from embodied_adhoc.teammates.grid_members import SeatTeam, StickyTeam
from embodied_adhoc.teammates.populations import SUITE_VERSION, find_member, members, population

FORAGING_ID = "EmbodiedAdhoc/ForagingGrid-v0"


def _episode(spec, seed: int, steps: int = 25, env=None) -> list:
    own = env is None
    env = env or gymnasium.make(FORAGING_ID, teams=[spec.plugin], disable_env_checker=True)
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


@pytest.mark.parametrize("spec", population("foraging"), ids=lambda s: s.name)
def test_foraging_members_are_deterministic_per_seed(spec):
    env = gymnasium.make(FORAGING_ID, teams=[spec.plugin], disable_env_checker=True)
    first = _episode(spec, 5, env=env)
    _episode(spec, 6, env=env)  # an episode between: a member's memory starts afresh with each seeded reset
    assert _episode(spec, 5, env=env) == first
    assert _episode(spec, 5) == first  # and a fresh env plays it alike
    env.close()


def test_foraging_population_shape():
    held_out = {s.name: s for s in members("foraging", "heldout")}
    # the ATLPO split's held-out teams are all held out here
    for tau in ("tau0", "tau1", "tau2"):
        assert held_out[f"{tau}-noise-p20"].params == {"family": "seats", "teams": [tau], "noise": NOISE}
    assert [s.params["teams"] for s in held_out.values() if s.name.startswith("mixed-")] == [
        list(types) for types in MIXED
    ]
    assert [s.name for s in members("foraging", "train")] == ["tau0", "tau1", "tau2"]
    learned = [s for s in population("foraging") if s.params["family"] == "learned"]
    assert {s.split for s in learned} == {"validation", "held-out"}
    for spec in learned:  # named by plug-in spec, weights shipped with the suite
        assert spec.plugin == f"embodied_adhoc.learning.bench_members:foraging/{spec.name}"
        assert callable(spec.factory())
    assert all(s.version == SUITE_VERSION for s in population("foraging"))


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

    options, max_steps = domain_defaults("foraging")
    return {**spec.trial_options(options), "bench_member": spec.describe()}, max_steps


def test_simulated_bounds_normalise_random_to_0_and_the_original_team_to_1(tmp_path):
    spec = find_member("foraging", "tau1-noise-p20")
    options, max_steps = _options(spec)
    # the original team alone (the trained best response's side: tests/bench/test_bench_best_response.py)
    bounds = simulated_bounds(
        "foraging", options, max_steps, tmp_path / "a", episodes=3, seed=2, trained=False
    )
    again = simulated_bounds(
        "foraging", options, max_steps, tmp_path / "b", episodes=3, seed=2, trained=False
    )
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


def test_tiny_grid_evaluate_gives_the_same_numbers_twice_and_after_resuming(tmp_path):
    specs = (find_member("foraging", "sticky-tau2-p50"), find_member("foraging", "tau0-noise-p20"))
    suite = Suite("heldout", SUITE_VERSION, {"foraging": specs})

    def run(out):
        return evaluate(
            ("random", "ppo-generalist"), suite, out, episodes=2, bound_episodes=2, plots=False, reps=50
        )

    first = run(tmp_path / "one")
    second = run(tmp_path / "two")
    resumed = run(tmp_path / "one")  # every trial stored: read back, not run again
    assert json.dumps(first, sort_keys=True) == json.dumps(second, sort_keys=True)
    assert json.dumps(first, sort_keys=True) == json.dumps(resumed, sort_keys=True)
    rows = first["domains"]["foraging"]["teammates"]
    assert [row["name"] for row in rows] == ["sticky-tau2-p50", "tau0-noise-p20"]
    for row in rows:
        assert row["bounds"]["upper"] in (ORIGINAL, TRAINED) and row["best_on_episodes"] is None
        assert row["bounds"]["random"] < row["bounds"]["best"]
        # both candidates are written, and the bound is the better one, named by its label
        candidates = {ORIGINAL: row["bounds"]["original"], TRAINED: row["bounds"]["trained"]}
        assert row["bounds"]["best"] == max(candidates.values()) == candidates[row["bounds"]["upper"]]
