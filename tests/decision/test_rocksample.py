"""RockSample[n, k]: sizes, dynamics, rewards and sensor of the generator; the CLI writes a file that reads back the
same model; ``--solver auto`` picks HSVI for it and Perseus for small or many-observation models."""

from __future__ import annotations

import json

import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.cli import main
from embodied_adhoc.commands.pomdp import auto_solver, solver_features
from embodied_adhoc.decision.pomdp_io import read_pomdp
from embodied_adhoc.decision.rocksample import rock_positions, rocksample
from embodied_adhoc.errors import ConfigError


@pytest.mark.parametrize(
    ("n", "k", "states", "actions"), [(4, 4, 257, 9), (5, 7, 3201, 12), (7, 8, 12545, 13)]
)
def test_sizes_are_the_classic_ones(n, k, states, actions):
    pomdp = rocksample(n, k, seed=3)
    assert (pomdp.n_states, pomdp.n_actions, pomdp.n_observations) == (states, actions, 2)
    assert pomdp.discount == 0.95
    assert np.count_nonzero(pomdp.initial_belief) == 2**k  # the start cell, rock qualities uniform


def test_dynamics_rewards_and_sensor():
    n, k = 3, 2
    pomdp = rocksample(n, k, seed=5)
    rocks = rock_positions(n, k, seed=5)
    assert len({tuple(cell) for cell in rocks.tolist()}) == k
    configs = 2**k

    def state(x, y, bits):
        return (y * n + x) * configs + bits

    def successor(s, action):
        row = pomdp.transitions[action].getrow(s)
        assert row.nnz == 1 and row.data[0] == 1.0  # deterministic
        return int(row.indices[0])

    exit_state = pomdp.n_states - 1
    assert successor(state(n - 1, 0, 3), 2) == exit_state and pomdp.rewards[state(n - 1, 0, 3), 2] == 10.0
    assert successor(state(0, 0, 1), 1) == state(0, 0, 1)  # south wall: stays, no reward
    assert pomdp.rewards[state(0, 0, 1), 1] == 0.0
    assert successor(state(0, 0, 1), 0) == state(0, 1, 1)  # north is y + 1
    x, y = rocks[0]
    assert pomdp.rewards[state(x, y, 0b01), 4] == 10.0 and successor(state(x, y, 0b01), 4) == state(x, y, 0)
    assert pomdp.rewards[state(x, y, 0b10), 4] == -10.0 and successor(state(x, y, 0b10), 4) == state(x, y, 2)
    assert all(successor(exit_state, a) == exit_state for a in range(pomdp.n_actions))
    assert not pomdp.rewards[exit_state].any()
    # check_0 from the cell farthest away: right with probability (1 + 2^(-d/20)) / 2, for good and bad rocks
    far = max(((cx, cy) for cx in range(n) for cy in range(n)), key=lambda c: np.hypot(c[0] - x, c[1] - y))
    eta = (1 + 2 ** (-np.hypot(far[0] - x, far[1] - y) / 20)) / 2
    good, bad = pomdp.observations[5].toarray()[[state(*far, 1), state(*far, 0)]]
    assert np.allclose(good, [eta, 1 - eta]) and np.allclose(bad, [1 - eta, eta]) and eta < 1
    assert np.allclose(pomdp.observations[5].toarray()[state(x, y, 1)], [1, 0])  # at the rock: exact
    assert all(np.all(pomdp.observations[a].toarray()[:, 1] == 1) for a in range(5))  # moves say nothing


def test_bad_sizes_are_refused():
    with pytest.raises(ConfigError, match="k = 10 rocks"):
        rocksample(3, 10)
    with pytest.raises(ConfigError, match="n must be"):
        rocksample(0, 1)


def test_cli_writes_a_file_that_reads_back(tmp_path, capsys):
    out = tmp_path / "rs.pomdp"
    flags = ["--n", "3", "--k", "2", "--seed", "4", "--out", str(out), "--json"]
    assert main(["pomdp", "generate", "rocksample", *flags]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["states"] == 37 and report["rocks"] == rock_positions(3, 2, 4).tolist()
    pomdp, built = read_pomdp(out), rocksample(3, 2, 4)
    assert all((a != b).nnz == 0 for a, b in zip(pomdp.transitions, built.transitions, strict=True))
    assert all((a != b).nnz == 0 for a, b in zip(pomdp.observations, built.observations, strict=True))
    assert np.array_equal(pomdp.rewards, built.rewards)
    assert main(["pomdp", "generate", "rocksample", "--n", "2", "--k", "9", "--out", str(out)]) == 2
    assert "k <= n^2" in capsys.readouterr().err


def test_auto_picks_hsvi_for_large_few_observation_models_only():
    assert auto_solver(3201, 2, 0.95, None) == "hsvi"  # RockSample[5, 7]
    assert auto_solver(200, 4, 0.95, None) == "hsvi"
    assert auto_solver(199, 2, 0.95, None) == "perseus"  # tiger-sized: Perseus' sampled set covers it
    assert auto_solver(870, 30, 0.95, None) == "perseus"  # Tag: many observations
    assert auto_solver(3201, 2, 0.95, 10) == "perseus"  # finite horizon: only Perseus solves it
    assert auto_solver(3201, 2, 1.0, None) == "perseus"


def test_auto_picks_hsvi_for_navigation_models_with_a_known_start_and_a_local_sensor():
    # the chapter-5 exports (isr: a start on 12 of 1,807 states, each state emitting 17 % of the 81 observations)
    assert auto_solver(1807, 81, 0.95, None, start_share=0.0066, observation_share=0.17) == "hsvi"
    # a dense observation model (the classic corpus's cit: 96 % of the observations from every state)
    assert auto_solver(284, 28, 0.95, None, start_share=0.0035, observation_share=0.96) == "perseus"
    # a spread start (Tag: 97 % of the states, one observation each)
    assert auto_solver(870, 30, 0.95, None, start_share=0.97, observation_share=0.033) == "perseus"
    assert auto_solver(150, 81, 0.95, None, start_share=0.01, observation_share=0.1) == "perseus"  # small


def test_solver_features_read_the_start_s_support_and_the_observations_each_state_emits():
    tiger = read_pomdp(paths.asset("data/tiger.95.POMDP"))
    assert solver_features(tiger) == {"start_share": 1.0, "observation_share": 1.0}
    rock = rocksample(3, 2, 4)  # the robot's cell is known, the rocks are not: 4 of 37 states at the start
    features = solver_features(rock)
    assert features["start_share"] == np.count_nonzero(rock.initial_belief) / rock.n_states < 0.25
    assert 0.0 < features["observation_share"] <= 1.0


def test_cli_auto_runs_hsvi_on_rocksample(tmp_path, capsys):
    out = tmp_path / "rs44.pomdp"
    assert main(["pomdp", "generate", "rocksample", "--n", "4", "--k", "4", "--out", str(out)]) == 0
    capsys.readouterr()
    flags = ["--trials", "2", "--threads", "1", "--json", "--quiet"]
    assert main(["pomdp", "solve", str(out), *flags]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["solver"] == "hsvi" and report["iterations"] == 2 and report["lower"] <= report["upper"]
