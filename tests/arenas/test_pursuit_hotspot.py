"""Fig. 7.12 on both backends: the pursuit POMDP as the arena's rules, HOTSPOT driving a physics episode."""

from __future__ import annotations

import subprocess
import sys

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401
from embodied_adhoc.decision.agents.factory import make_agent
from embodied_adhoc.envs.pursuit_pomdp import (
    MOVES,
    cells_of_state,
    offset_index,
    pursuit_pair_library,
    state_index,
)
from embodied_adhoc.errors import ConfigError

GRID, PHYSICS = "EmbodiedAdhoc/PursuitPairPomdpGrid-v0", "EmbodiedAdhoc/PursuitPairPomdp-v0"


def test_cells_and_states_agree_with_the_library():
    """Every live library state maps to cells and back, from any agent cell; every transition of the library
    moves the teammate and the prey by one of the five moves (the library's dynamics, read as robot moves)."""
    library = pursuit_pair_library()
    live = np.arange(library.absorbing_state)
    rng = np.random.default_rng(0)
    for x in live:
        agent = rng.integers(5, size=2)
        assert state_index(cells_of_state(x, agent)) == x
    move_indices = {int(offset_index(m)) for m in MOVES}
    for pomdp in library.pomdps:
        for a in range(5):
            matrix = pomdp.transitions[a].tocoo()
            keep = (matrix.row < library.absorbing_state) & (matrix.col < library.absorbing_state)
            for x, y in zip(matrix.row[keep][::7], matrix.col[keep][::7], strict=True):
                before = cells_of_state(x, np.array([2, 2]))
                after = cells_of_state(y, (np.array([2, 2]) + MOVES[a]) % 5)
                for robot in (1, 2):
                    assert int(offset_index(after[robot] - before[robot])) in move_indices


@pytest.mark.parametrize("env_id", [GRID, PHYSICS])
def test_observations_come_from_the_pomdps_observation_rows(env_id):
    env = gymnasium.make(env_id)
    library = env.unwrapped.library
    _, info = env.reset(seed=4, options={"task": 2})
    rng = np.random.default_rng(1)
    for _ in range(8):
        action = int(rng.integers(5))
        z, _, terminated, truncated, info = env.step(action)
        assert z == info["observation_index"]
        assert library.pomdps[2].observations[action][info["state"], z] > 0.0
        assert info["state"] == state_index(np.array(info["cells"]))
        if terminated or truncated:
            break
    env.close()


def test_noise_free_observation_is_the_neighbourhood():
    env = gymnasium.make(GRID, noise=0.0)
    env.reset(seed=0, options={"task": 0, "start": 0, "agent_cell": [2, 2]})
    _, _, _, _, info = env.step(4)
    cells = np.array(info["cells"])
    expected = []
    for robot in (1, 2):
        d = (cells[robot] - cells[0] + 2) % 5 - 2
        expected.append(3 * (d[0] + 1) + d[1] + 1 if np.abs(d).max() <= 1 and np.abs(d).sum() > 0 else 4)
    assert info["observation_index"] == 9 * expected[0] + expected[1]


def test_same_seed_same_episode_on_both_backends():
    """Same draws on both backends: with physics executing every move, the state sequences are identical."""
    histories = []
    for env_id in (GRID, PHYSICS):
        env = gymnasium.make(env_id)
        _, info = env.reset(seed=11, options={"task": 1})
        states = [info["state"]]
        for action in (0, 3, 3, 1, 4, 2):
            _, _, terminated, _, info = env.step(action)
            states.append(info["state"])
            if terminated:
                break
        histories.append(states)
        env.close()
    assert histories[0] == histories[1]


def test_hotspot_captures_in_physics_and_its_posterior_concentrates_on_the_true_task():
    env = gymnasium.make(PHYSICS)
    library = env.unwrapped.library
    agent = make_agent("hotspot", library)
    true_task = 3
    _, info = env.reset(seed=5, options={"task": true_task})
    agent.reset(np.random.default_rng(5))
    assert np.allclose(agent.task_posterior, 0.25)
    terminated = False
    for _ in range(150):
        action = agent.act()
        z, reward, terminated, truncated, info = env.step(action)
        agent.observe(action, int(z))  # the agent's observation is obs (info: ground truth, for the checks)
        assert info["state"] == info["intended_state"]  # physics executed the drawn move
        if terminated or truncated:
            break
    env.close()
    assert terminated and reward == 1.0
    assert agent.task_posterior.argmax() == true_task
    assert agent.task_posterior[true_task] > 0.9


def test_bad_reset_options_and_kwargs_are_refused():
    env = gymnasium.make(GRID)
    with pytest.raises(ConfigError, match="start"):
        env.reset(seed=0, options={"task": 0, "start": 625})  # the absorbing state
    with pytest.raises(ConfigError, match="task"):
        env.reset(seed=0, options={"task": 4})
    with pytest.raises(ConfigError):
        gymnasium.make(GRID, physics=object())


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args], capture_output=True, text=True, timeout=300
    )


@pytest.mark.slow
def test_trials_pairs_with_decision_agents_and_refusals(tmp_path):
    done = _cli("trials", "pursuit", "--pairs", "--agents", "hotspot,oracle", "--episodes", "2", "--json")
    assert done.returncode == 0, done.stderr
    assert '"hotspot"' in done.stdout and '"rules": "pomdp"' in done.stdout
    # a run folder is identified by its inputs: the POMDP variant reads no file
    stored = _cli(
        "trials", "pursuit", "--pairs", "--agents", "hotspot", "--episodes", "1", "--out", str(tmp_path)
    )
    assert stored.returncode == 0, stored.stderr
    assert (tmp_path / "trials.csv").is_file()
    mixed = _cli("trials", "pursuit", "--pairs", "--agents", "original,hotspot", "--episodes", "1")
    assert mixed.returncode == 2 and "original" in mixed.stderr
    unpaired = _cli("trials", "pursuit", "--agents", "hotspot", "--episodes", "1")
    assert unpaired.returncode == 2 and "--pairs" in unpaired.stderr


def test_run_foraging_without_a_library_is_refused_with_the_training_command(tmp_path):
    done = _cli("run", "foraging", "--library", str(tmp_path))
    assert done.returncode == 2
    assert "embodied-adhoc train atlpo --domain foraging" in done.stderr


@pytest.mark.parametrize("env_id", ["EmbodiedAdhoc/PursuitPairGrid-v0", "EmbodiedAdhoc/PursuitPair-v0"])
def test_the_rule_based_pair_envs_expose_the_pomdps_observation_index(env_id):
    """Same observation function as the library (noise 0: the neighbourhood itself), and the other draws of the
    env are unchanged by it (the teammate's actions do not depend on the noise level)."""
    runs = {}
    for noise in (0.0, 0.5):
        env = gymnasium.make(env_id, observation_noise=noise)
        observation, info = env.reset(seed=3, options={"task": 1, "team": "greedy"})
        assert observation["observation_index"] == 40 and "observation_index" not in info
        assert env.observation_space.contains(observation)
        trace = []
        for action in (0, 3, 1, 2, 4, 0):
            observation, _, terminated, _, info = env.step(action)
            state = info["state"]
            offsets = np.array([state["agents"][1], state["targets"][0]]) - np.array(state["agents"][0])
            expected = [
                3 * (d[0] + 1) + d[1] + 1 if np.abs(d).max() <= 1 and np.abs(d).sum() else 4 for d in offsets
            ]
            if noise == 0.0:
                assert observation["observation_index"] == 9 * expected[0] + expected[1]
            trace.append((info["teammate_actions"], state["targets"]))
            if terminated:
                break
        runs[noise] = trace
        env.close()
    assert runs[0.0] == runs[0.5]


@pytest.mark.slow
def test_run_pursuit_records_video_rerun_and_metrics(tmp_path):
    """``run pursuit --record``: the mp4 has frames, the rrd holds poses, posterior bars, entropy, observations,
    actions and overhead frames, metrics.json replays the trial runner's episode 0."""
    import json

    import imageio.v3 as iio
    from rerun.chunk import RrdReader

    done = _cli(
        "run",
        "pursuit",
        "--agent",
        "hotspot",
        "--seed",
        "0",
        "--size",
        "160",
        "--record",
        str(tmp_path),
        "--no-progress",
        "--json",
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["success"] and summary["physics_mismatches"] == 0
    assert len(iio.imread(tmp_path / "episode.mp4")) > summary["steps"]
    entities = {
        chunk.entity_path.lstrip("/")
        for chunk in RrdReader(tmp_path / "episode.rrd").store().stream().to_chunks()
    }
    for entity in (
        "world/arena/cells",
        "world/arena/robots",
        "world/arena/headings",
        "belief/task",
        "belief/entropy",
        "log/observations",
        "log/actions",
        "log/events",
        "camera/overhead",
    ):
        assert entity in entities, entity
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["config"]["env"] == PHYSICS and len(metrics["per_step"]) == summary["steps"]
    trial = _cli(
        "trials",
        "pursuit",
        "--pairs",
        "--backend",
        "mujoco",
        "--agents",
        "hotspot",
        "--episodes",
        "1",
        "--json",
    )
    assert json.loads(trial.stdout)["agents"]["hotspot"]["steps_mean"] == summary["steps"]
