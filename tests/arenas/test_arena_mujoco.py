"""MuJoCo arenas: compile without warnings, execute grid plans physically, check_env and determinism."""

import gymnasium
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import embodied_adhoc.envs  # noqa: F401
from embodied_adhoc.domains.foraging import foraging_config, foraging_tasks
from embodied_adhoc.domains.grid_rules import DOWN, INTERACT, LEFT, RIGHT, UP, GridRules, GridState
from embodied_adhoc.domains.pursuit import pursuit_config, pursuit_tasks
from embodied_adhoc.sim.grid_arena import ArenaLayout
from embodied_adhoc.sim.grid_arena_world import GridArenaBackend


def test_layout_maps_cells_both_ways():
    layout = ArenaLayout(4, 6, 0.25)
    cells = np.array([[0, 0], [3, 5], [2, 1]])
    assert np.array_equal(layout.xy_cell(layout.cell_xy(cells)), cells)
    assert layout.cell_xy([0, 0])[1] > layout.cell_xy([3, 0])[1]  # row 0 is north


@pytest.mark.parametrize(
    "config", [foraging_config(rows=6, cols=8, n_agents=2, n_targets=2), pursuit_config(n_agents=3)]
)
def test_arena_compiles_and_rests_without_warnings(config):
    backend = GridArenaBackend(GridRules(config))
    backend.reset(GridRules(config).sample_state(np.random.default_rng(0)))
    mujoco.mj_step(backend.model, backend.data, 200)
    assert all(w.lastinfo == 0 and w.number == 0 for w in backend.data.warning)
    assert np.abs(backend.data.qvel).max() < 0.05  # robots settle on their wheels and casters


def test_robots_drive_to_the_planned_cells_and_apples_vanish_when_foraged():
    rules = GridRules(foraging_config())
    backend = GridArenaBackend(rules)
    state = GridState(
        np.array([[0, 0], [3, 2], [2, 1], [4, 4]]), np.ones(4, int), np.array([[2, 2]]), np.array([4])
    )
    state = backend.reset(state)
    rng = np.random.default_rng(0)
    plan = rules.plan(state, foraging_tasks()[0], np.array([RIGHT, INTERACT, INTERACT, DOWN]), rng)
    state = backend.execute(state, plan)
    assert state.agents.tolist() == [[0, 1], [3, 2], [2, 1], [4, 4]]
    assert np.abs(backend.poses()[0, :2] - backend.layout.cell_xy([0, 1])).max() < 0.03
    for joint in ([RIGHT, 4, 4, UP], [DOWN, 4, 4, UP], [4, 4, 4, LEFT], [4, 4, 4, 4]):
        state = backend.execute(state, rules.plan(state, foraging_tasks()[0], np.array(joint), rng))
    assert state.agents[[0, 3]].tolist() == [[1, 2], [2, 3]] and not state.alive.any()
    assert backend.model.geom_rgba[backend.apple_geoms[0], 3] == 0.0


@pytest.mark.parametrize(
    "env_id", ["EmbodiedAdhoc/Foraging-v0", "EmbodiedAdhoc/Pursuit-v0", "EmbodiedAdhoc/PursuitPair-v0"]
)
def test_mujoco_env_checks_and_determinism(env_id):
    env = gymnasium.make(env_id, rows=5, cols=5)
    check_env(env.unwrapped, skip_render_check=True)
    traces = []
    for seed in (3, 3):
        obs, info = env.reset(seed=seed)
        space = (
            env.observation_space
        )  # the pursuit pairs' is a Dict (view and POMDP index): compared flattened
        trace = [gymnasium.spaces.flatten(space, obs)]
        for action in (0, 3, 1, 4):
            obs, *_, info = env.step(action)
            trace.append(gymnasium.spaces.flatten(space, obs))
        traces.append((np.stack(trace), info["state"]))
    assert np.array_equal(traces[0][0], traces[1][0]) and traces[0][1] == traces[1][1]
    env.close()


def test_image_observation_and_render():
    env = gymnasium.make("EmbodiedAdhoc/Pursuit-v0", obs_mode="image", image_size=32, render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (32, 32, 3) and obs.dtype == np.uint8 and obs.std() > 0
    assert env.observation_space.contains(obs)
    assert env.render().shape == (480, 480, 3)
    env.close()


def test_physics_reads_back_exactly_what_the_rules_planned():
    """The twins agree step by step: random joint actions, moving prey, every robot lands on its planned cell."""
    rules = GridRules(pursuit_config())
    backend = GridArenaBackend(rules)
    rng = np.random.default_rng(2)
    state = backend.reset(rules.sample_state(rng))
    task = pursuit_tasks()[0]
    for _ in range(12):
        plan = rules.plan(state, task, rng.integers(0, 5, size=4), rng)
        state = backend.execute(state, plan)
        assert np.array_equal(state.agents, plan.agents) and np.array_equal(state.targets, plan.targets)


def test_toroidal_arena_is_refused():
    from embodied_adhoc.errors import ConfigError

    with pytest.raises(ConfigError, match="toroidal"):
        gymnasium.make("EmbodiedAdhoc/Foraging-v0", toroidal=True)
