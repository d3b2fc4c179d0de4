"""Grid rules (thesis 6.2.1), observations and scripted teams (6.2.2)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from embodied_adhoc.domains.foraging import foraging_config, foraging_tasks
from embodied_adhoc.domains.grid_rules import DOWN, INTERACT, LEFT, RIGHT, UP, GridRules, GridState
from embodied_adhoc.domains.grid_rules_obs import egocentric_observation, observation_channels
from embodied_adhoc.domains.grid_rules_team import team_actions
from embodied_adhoc.domains.pursuit import pursuit_config, pursuit_tasks, two_predator_config
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.teammates.foraging_teams import FORAGING_TEAMS
from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS


def lbf_state(agents, levels, apple, apple_level):
    return GridState(np.array(agents), np.array(levels), np.array([apple]), np.array([apple_level]))


def test_forage_needs_positions_all_forage_and_levels():
    rules, task = GridRules(foraging_config()), foraging_tasks()[0]  # agents 0..3 at N, S, W, E
    rng = np.random.default_rng(0)
    around = [[1, 2], [3, 2], [2, 1], [2, 3]]
    state = lbf_state(around, [1, 1, 1, 1], [2, 2], 4)
    assert rules.plan(state, task, np.full(4, INTERACT), rng).completed.all()
    assert not rules.plan(state, task, np.array([INTERACT] * 3 + [UP]), rng).completed.any()
    assert not rules.plan(
        lbf_state(around, [1, 1, 1, 1], [2, 2], 5), task, np.full(4, INTERACT), rng
    ).completed.any()
    swapped = lbf_state([[3, 2], [1, 2], [2, 3], [2, 1]], [1, 1, 1, 1], [2, 2], 1)
    assert not rules.plan(swapped, task, np.full(4, INTERACT), rng).completed.any()
    assert rules.plan(swapped, foraging_tasks()[2], np.full(4, INTERACT), rng).completed.all()  # rotated 180


def test_moves_blocked_by_walls_occupants_and_shared_claims():
    rules = GridRules(foraging_config())
    state = lbf_state([[0, 0], [0, 2], [1, 2], [4, 4]], [1, 1, 1, 1], [2, 2], 1)
    plan = rules.plan(state, foraging_tasks()[0], np.array([UP, LEFT, DOWN, RIGHT]), np.random.default_rng(0))
    # 0 and 3 hit walls, 1 moves, 2 would enter the apple's cell
    assert plan.agents.tolist() == [[0, 0], [0, 1], [1, 2], [4, 4]]
    clash = lbf_state([[0, 0], [0, 2], [3, 3], [4, 4]], [1, 1, 1, 1], [2, 2], 1)
    plan = rules.plan(
        clash, foraging_tasks()[0], np.array([RIGHT, LEFT, INTERACT, INTERACT]), np.random.default_rng(0)
    )
    assert plan.agents[:2].tolist() == [[0, 0], [0, 2]]
    torus = GridRules(foraging_config(toroidal=True))
    plan = torus.plan(
        state, foraging_tasks()[0], np.array([UP, INTERACT, INTERACT, RIGHT]), np.random.default_rng(0)
    )
    assert plan.agents[[0, 3]].tolist() == [[0, 0], [4, 4]]  # both wrap onto (4, 0): the shared claim fails
    plan = torus.plan(
        state, foraging_tasks()[0], np.array([UP, INTERACT, INTERACT, UP]), np.random.default_rng(0)
    )
    assert plan.agents[[0, 3]].tolist() == [[4, 0], [3, 4]]


def test_two_predator_capture_is_automatic_and_interchangeable():
    rules, tasks = GridRules(two_predator_config()), pursuit_tasks(pairs=True)
    state = GridState(np.array([[3, 2], [1, 2]]), np.ones(2, int), np.array([[2, 2]]), np.ones(1, int))
    assert rules.plan(
        state, tasks[0], np.array([INTERACT, INTERACT]), np.random.default_rng(0)
    ).completed.all()
    assert not rules.plan(
        state, tasks[1], np.array([INTERACT, INTERACT]), np.random.default_rng(0)
    ).completed.any()


def test_prey_stays_inside_and_off_agents():
    rules = GridRules(pursuit_config())
    rng = np.random.default_rng(3)
    state = rules.sample_state(rng)
    for _ in range(200):
        plan = rules.plan(state, pursuit_tasks()[0], rng.integers(0, 5, size=4), rng)
        state = rules.apply(state, plan)
        assert rules.target_cells_valid(state.targets).all()
        cells = {tuple(c) for c in state.agents.tolist()} | {tuple(state.targets[0])}
        assert len(cells) == 5


def test_observation_channels_and_boundary():
    rules = GridRules(foraging_config())
    state = lbf_state([[0, 0], [0, 2], [3, 3], [4, 4]], [2, 1, 1, 1], [2, 2], 3)
    obs = egocentric_observation(rules, state, 0)
    assert obs.shape == (observation_channels(rules), 5, 5) == (6, 5, 5)
    assert (
        obs[0, 2, 4] == 1 and obs[1].sum() == 0 and obs[1 - 1 + 3, 4, 4] == 1
    )  # teammate 1; apple at (+2,+2)
    assert obs[4, :2].all() and obs[4, 2:, 2:].sum() == 0  # boundary above and left
    assert obs[5, 2, 2] == 2 and obs[5, 4, 4] == 3  # own level, apple level
    assert observation_channels(GridRules(pursuit_config())) == 5
    with pytest.raises(ConfigError):
        egocentric_observation(rules, state, 0, view=4)


@pytest.mark.parametrize(
    ("make", "tasks", "teams"),
    [
        (foraging_config, foraging_tasks(), FORAGING_TEAMS),
        (pursuit_config, pursuit_tasks(), {k: PURSUIT_TEAMS[k] for k in ("tau0", "tau1", "tau2")}),
        (two_predator_config, pursuit_tasks(pairs=True), {k: PURSUIT_TEAMS[k] for k in ("greedy", "aware")}),
    ],
)
def test_every_team_solves_every_task(make, tasks, teams):
    rules = GridRules(make())
    for spec in teams.values():
        for task in tasks:
            rng = np.random.default_rng(1)
            for _ in range(4):
                state = rules.sample_state(rng)
                for _ in range(100):
                    state = rules.apply(
                        state, rules.plan(state, task, team_actions(rules, state, task, spec, rng), rng)
                    )
                    if not state.alive.any():
                        break
                assert not state.alive.any(), (spec.name, task.name)


def test_config_errors_name_the_field():
    with pytest.raises(ConfigError, match="n_agents"):
        foraging_config(n_agents=5)
    with pytest.raises(ConfigError, match="3x3"):
        foraging_config(rows=3, cols=3)
    foraging_config(rows=3, cols=3, toroidal=True)


def reference_observation(rules, state, agent, view):
    """Cell-by-cell definition of the egocentric observation (thesis 6.2.1), to check the vectorised one."""
    cfg = rules.config
    half = view // 2
    obs = np.zeros((observation_channels(rules), view, view), dtype=np.float32)
    mates = [j for j in range(cfg.n_agents) if j != agent]
    for dr in range(-half, half + 1):
        for dc in range(-half, half + 1):
            cell, inside = rules.normalise(state.agents[agent] + np.array([dr, dc]))
            i, j = dr + half, dc + half
            if not inside:
                obs[len(mates) + cfg.n_targets, i, j] = 1
                continue
            for k, mate in enumerate(mates):
                if (state.agents[mate] == cell).all():
                    obs[k, i, j] = 1
                    if cfg.domain == "foraging":
                        obs[-1, i, j] = state.agent_levels[mate]
            if (state.agents[agent] == cell).all() and cfg.domain == "foraging":
                obs[-1, i, j] = state.agent_levels[agent]
            for m in range(cfg.n_targets):
                if state.alive[m] and (state.targets[m] == cell).all():
                    obs[len(mates) + m, i, j] = 1
                    if cfg.domain == "foraging":
                        obs[-1, i, j] = state.target_levels[m]
    return obs


@pytest.mark.parametrize(
    "config",
    [
        foraging_config(n_targets=2),
        foraging_config(rows=4, cols=6, toroidal=True),
        pursuit_config(n_agents=3, rows=6, cols=5),
        pursuit_config(toroidal=True),
    ],
)
def test_vectorised_observation_matches_definition(config):
    from embodied_adhoc.domains.grid_rules_obs import egocentric_observations

    rules, rng = GridRules(config), np.random.default_rng(4)
    for _ in range(20):
        state = rules.sample_state(rng)
        state.alive[0] = rng.random() < 0.7
        every = egocentric_observations(rules, state, 5)
        for agent in range(config.n_agents):
            expected = reference_observation(rules, state, agent, 5)
            assert np.array_equal(egocentric_observation(rules, state, agent, 5), expected)
            assert np.array_equal(every[agent], expected)


@settings(max_examples=40, deadline=None)
@given(
    domain=st.sampled_from(["foraging", "pursuit"]),
    rows=st.integers(5, 8),
    cols=st.integers(5, 8),
    n_agents=st.integers(2, 4),
    n_targets=st.integers(1, 2),
    toroidal=st.booleans(),
    seed=st.integers(0, 10**6),
)
def test_any_step_keeps_cells_on_the_grid_and_distinct(
    domain, rows, cols, n_agents, n_targets, toroidal, seed
):
    from embodied_adhoc.domains.grid_rules import GridConfig, rotation_tasks

    rules = GridRules(
        GridConfig(
            domain=domain, rows=rows, cols=cols, n_agents=n_agents, n_targets=n_targets, toroidal=toroidal
        )
    )
    rng = np.random.default_rng(seed)
    state = rules.sample_state(rng)
    for _ in range(15):
        before, previous = state.alive.copy(), state.agents.copy()
        state = rules.apply(
            state, rules.plan(state, rotation_tasks(n_agents)[0], rng.integers(0, 5, n_agents), rng)
        )
        live = [tuple(c) for c in state.targets[state.alive].tolist()]
        cells = [tuple(c) for c in state.agents.tolist()] + live
        assert len(set(cells)) == len(cells)
        assert (
            rules.normalise(state.agents)[1].all()
            and rules.target_cells_valid(state.targets[state.alive]).all()
        )
        assert not (state.alive & ~before).any()  # taken targets never come back
        assert (rules.distance(previous, state.agents) <= 1).all()  # one cell per step at most
