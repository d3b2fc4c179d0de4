"""PettingZoo ParallelEnv of the arenas: PettingZoo's API test, seeded determinism, the team solving it."""

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from embodied_adhoc.envs.multiagent import GridParallelEnv


@pytest.mark.parametrize("kwargs", [{"domain": "foraging"}, {"domain": "pursuit", "pairs": True}])
def test_parallel_api(kwargs):
    parallel_api_test(GridParallelEnv(**kwargs), num_cycles=50)


def test_parallel_seeded_and_solvable_by_the_team():
    env = GridParallelEnv("pursuit", teams=("tau1",))
    runs = []
    for _ in range(2):
        obs, infos = env.reset(seed=11)
        history = []
        while env.agents:
            actions = dict(
                zip(env.possible_agents, env.core.scripted_actions(range(4)).tolist(), strict=True)
            )
            obs, rewards, terminations, truncations, infos = env.step(actions)
            history.append(env.state())
        runs.append(np.stack(history))
    assert np.array_equal(runs[0], runs[1])
    assert all(terminations.values()) and rewards["agent_0"] == 1.0
