"""The vectorised grid core against the single env (thesis section 6.2; issue 15 item 1)."""

import gymnasium
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.vector_grid import GRID_IDS, GridVectorEnv

CASES = [
    ("foraging", {}),
    ("pursuit", {}),
    ("foraging", {"teams": ("tau2",), "tasks": (3,), "toroidal": True}),
    ("foraging", {"n_apples": 2, "rows": 6, "cols": 7}),
    ("pursuit", {"pairs": True}),
    ("pursuit", {"n_agents": 3, "toroidal": True, "rows": 6}),
]


def views(observations):
    """The single env's observation as the vector env gives it: the pursuit-pair envs observe a Dict of the
    agent's view and the pair POMDP's index; learners take the view only."""
    return observations["view"] if isinstance(observations, dict) else observations


def reference_vector(domain, num_envs, max_steps, kwargs):
    return gymnasium.vector.SyncVectorEnv(
        [
            lambda: gymnasium.make(GRID_IDS[domain], max_episode_steps=max_steps, **kwargs)
            for _ in range(num_envs)
        ],
        autoreset_mode=gymnasium.vector.AutoresetMode.NEXT_STEP,
    )


@pytest.mark.parametrize(("domain", "kwargs"), CASES)
def test_vector_env_matches_the_single_env_step_for_step(domain, kwargs):
    """Every sub-env equals a SyncVectorEnv of the registered single env: observations, rewards, flags,
    autoresets (NEXT_STEP) and the episode's task/team, over every team and task the library draws."""
    num_envs, max_steps = 12, 25
    fast = GridVectorEnv(domain, num_envs, max_episode_steps=max_steps, **kwargs)
    slow = reference_vector(domain, num_envs, max_steps, kwargs)
    for seed in (0, 100):
        obs, info = fast.reset(seed=seed)
        ref_obs, ref_info = slow.reset(seed=seed)
        assert np.array_equal(obs, views(ref_obs))
        assert np.array_equal(info["task"], ref_info["task"])
        assert [fast.team_names[t] for t in info["team"]] == list(ref_info["team"])
        actions_rng = np.random.default_rng(seed)
        ended = 0
        for _ in range(120):
            actions = actions_rng.integers(0, 5, num_envs)
            obs, reward, terminated, truncated, info = fast.step(actions)
            ref = slow.step(actions)
            assert np.array_equal(obs, views(ref[0]))
            assert np.array_equal(reward, ref[1])
            assert np.array_equal(terminated, ref[2]) and np.array_equal(truncated, ref[3])
            assert [fast.team_names[t] for t in info["team"]] == list(ref[4]["team"])
            ended += int(terminated.sum() + truncated.sum())
        assert ended > num_envs  # autoresets were exercised


def test_vector_env_seeding_is_deterministic_and_checks_actions():
    first, second = GridVectorEnv("pursuit", 4), GridVectorEnv("pursuit", 4)
    a, _ = first.reset(seed=7)
    b, _ = second.reset(seed=7)
    assert np.array_equal(a, b)
    for _ in range(30):
        actions = np.array([0, 1, 4, 3])
        assert np.array_equal(first.step(actions)[0], second.step(actions)[0])
    assert first.observation_space.shape == (4, 5, 5, 5)
    with pytest.raises(ConfigError, match="actions"):
        first.step(np.array([0, 1, 5, 3]))
    with pytest.raises(ConfigError, match="actions"):
        first.step(np.array([0, 1, 2]))
    with pytest.raises(ConfigError, match="backend"):
        GridVectorEnv("foraging", 2, backend="mujoco")


def test_vector_env_draws_listed_environments():
    env = GridVectorEnv("foraging", 16, environments=[(2, "tau0"), (3, "tau2")])
    _, info = env.reset(seed=0)
    pairs = {(int(t), env.team_names[m]) for t, m in zip(info["task"], info["team"], strict=True)}
    assert pairs == {(2, "tau0"), (3, "tau2")}
    with pytest.raises(ConfigError, match="environments"):
        GridVectorEnv("foraging", 2, environments=[(5, "tau0")])


@settings(max_examples=8, deadline=None)
@given(
    domain=st.sampled_from(["foraging", "pursuit"]),
    rows=st.integers(5, 7),
    cols=st.integers(5, 7),
    n_agents=st.integers(2, 4),
    toroidal=st.booleans(),
    seed=st.integers(0, 10**6),
)
def test_vector_env_matches_the_single_env_on_random_configurations(
    domain, rows, cols, n_agents, toroidal, seed
):
    kwargs = {"rows": rows, "cols": cols, "n_agents": n_agents, "toroidal": toroidal}
    fast = GridVectorEnv(domain, 4, max_episode_steps=15, **kwargs)
    slow = reference_vector(domain, 4, 15, kwargs)
    assert np.array_equal(fast.reset(seed=seed)[0], slow.reset(seed=seed)[0])
    actions_rng = np.random.default_rng(seed)
    for _ in range(40):
        actions = actions_rng.integers(0, 5, 4)
        for mine, theirs in zip(fast.step(actions)[:4], slow.step(actions)[:4], strict=True):
            assert np.array_equal(mine, theirs)


@pytest.mark.parametrize("toroidal", [False, True])
def test_move_table_answers_like_the_search(toroidal):
    """The vector env's lookup table (MoveTable) gives the breadth-first search's moves for random starts, goals
    and blocked sets of up to n_agents - 1 + n_targets cells (the single env searches; both must agree)."""
    from embodied_adhoc.domains.grid_rules import GridConfig, GridRules
    from embodied_adhoc.domains.grid_rules_plan import CellBits, best_moves, move_table

    rules = GridRules(GridConfig(toroidal=toroidal))
    bits = CellBits(rules)
    table = move_table(bits, 4)
    rng = np.random.default_rng(3)
    start, goal = rng.integers(0, 25, (2, 300, 4))
    cells = rng.integers(0, 26, (300, 4, 4))  # 25: no cell
    cells[0, 0] = np.where(rules.neighbours[start[0, 0]] >= 0, rules.neighbours[start[0, 0]], 25)  # boxed in
    goal[0, 0] = (start[0, 0] + 12) % 25
    blocked = bits.union(bits.of(np.where(cells == 25, -1, cells)), axis=2)
    searched = best_moves(bits, bits.neighbour_bits[start], bits.of(goal), blocked)
    assert np.array_equal(table.lookup(start, goal, blocked), searched)
    assert (searched > 0).mean() > 0.5 and (searched == 0).any()  # both reachable and walled-off goals occur
    assert (
        table.lookup(
            start,
            goal,
            blocked
            | bits.of(np.full_like(goal, 24))
            | bits.of(np.full_like(goal, 23))
            | bits.of(np.full_like(goal, 22))
            | bits.of(np.full_like(goal, 21)),
        )
        is None
    )  # > 4 cells


@pytest.mark.parametrize(
    "config",
    [{}, {"domain": "pursuit"}, {"rows": 6, "cols": 7, "n_targets": 2, "n_agents": 4, "toroidal": True}],
)
def test_batched_reset_states_draw_what_each_generator_draws_alone(config):
    """Row k of sample_states equals sample_state from a copy of Generator k, and every Generator ends where
    the single draw leaves it (the batched reset keeps each sub-env's stream)."""
    from embodied_adhoc.domains.grid_rules import GridConfig, GridRules

    rules = GridRules(GridConfig(**config))
    batched = [np.random.default_rng(seed) for seed in range(40)]
    alone = [np.random.default_rng(seed) for seed in range(40)]
    batch, _ = rules.sample_states(batched)
    for k, rng in enumerate(alone):
        state, row = rules.sample_state(rng), batch.state(k)
        for name in ("agents", "agent_levels", "targets", "target_levels", "alive"):
            assert np.array_equal(getattr(state, name), getattr(row, name))
        assert len({tuple(c) for c in np.concatenate([row.agents, row.targets])}) == len(row.agents) + len(
            row.targets
        )  # no two on a cell
        assert batched[k].random() == rng.random()
