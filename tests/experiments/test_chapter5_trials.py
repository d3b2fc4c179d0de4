"""Chapter-5 trials: every agent through the one trial runner, shared episodes, seeding, the policy cache, CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.experiments.domains.chapter5 import CHAPTER5_AGENTS
from embodied_adhoc.experiments.policy_cache import cache_dir, solve_cached
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

ROOT = Path(__file__).resolve().parents[2]


def _options(cache: bool = False, **library) -> dict:
    return {
        "library": library,
        "task": None,
        "beliefs": 60,
        "solve_stages": 10,
        "solve_seconds": None,
        "cache": cache,
    }


@pytest.fixture()
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path / "xdg"


def test_every_agent_runs_on_the_same_episodes(private_cache):
    options = _options(map=str(_corridor(private_cache.parent)))
    config = SweepConfig("map", "abstract", options, CHAPTER5_AGENTS, episodes=3, seed=5, max_steps=30)
    result = run_sweep(config)
    by_agent = {agent: [r for r in result.records if r.agent == agent] for agent in CHAPTER5_AGENTS}
    specs = [[(r.spec["task"], r.spec["start"]) for r in rows] for rows in by_agent.values()]
    assert all(s == specs[0] for s in specs)
    summary = result.summary().agents
    assert summary["value-iteration"].success_rate == 1.0
    assert summary["value-iteration"].total_reward.mean > summary["random"].total_reward.mean
    # the same seed gives the same trials
    again = run_sweep(config)
    assert [(r.agent, r.steps, r.total_reward) for r in again.records] == [
        (r.agent, r.steps, r.total_reward) for r in result.records
    ]


def _corridor(folder: Path) -> Path:
    path = folder / "corridor.txt"
    path.write_text("S...G\n#.#.#\nS...G\n")
    return path


def test_policy_cache_round_trip_and_bypass(private_cache):
    pomdp = build_library("panic-buttons", size=3, teammate="optimal").pomdps[0]
    settings = {"n_beliefs": 40, "tolerance": 0.01, "time_limit": 5.0, "seed": 0}
    assert cache_dir() == private_cache / "embodied-adhoc" / "policies"
    first, hit = solve_cached(pomdp, settings)
    assert not hit and len(list(cache_dir().glob("*.npz"))) == 1
    second, hit = solve_cached(pomdp, settings)
    assert hit
    np.testing.assert_array_equal(first.alphas, second.alphas)
    _, hit = solve_cached(pomdp, {**settings, "n_beliefs": 41})
    assert not hit and len(list(cache_dir().glob("*.npz"))) == 2
    _, hit = solve_cached(pomdp, settings, use_cache=False)
    assert not hit and len(list(cache_dir().glob("*.npz"))) == 2


def test_power_plant_offers_no_bopa():
    from embodied_adhoc.experiments.registry import get_trial_domain

    assert "bopa" not in get_trial_domain("power-plant").agent_names
    assert "bopa" in get_trial_domain("gridworld").agent_names


def _cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "trials", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )


def test_cli_json_fields_and_help_shows_the_cache(tmp_path):
    import os

    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    help_text = _cli("ntu", "--help", env=env).stdout
    # argparse wraps the long path (also at hyphens): compare without whitespace
    assert str(tmp_path / "xdg" / "embodied-adhoc" / "policies") in "".join(help_text.split())
    result = _cli(
        "panic-buttons", "--size", "3", "--agents", "value-iteration,bopa,atpo,random", "--episodes", "3",
        "--beliefs", "40", "--solve-stages", "10", "--json", env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    for name in ("value-iteration", "bopa", "atpo", "random"):
        fields = document["agents"][name]
        for key in ("return_mean", "return_ci95", "steps_mean", "success_rate", "identify_steps_mean"):
            assert key in fields
    assert document["config"]["max_steps"] == 2000
    assert document["timing"]["solver_settings"]["max_iterations"] == 10
    assert document["timing"]["solver_settings"]["time_limit"] is None
    refused = _cli("ntu", "--episodes", "1", "--solve-stages", "0", env=env)
    assert refused.returncode == 2 and "--solve-stages: 0: give an integer >= 1" in refused.stderr


def test_cli_refuses_a_bad_map_with_its_place(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("S..G\nS.%G\n")
    result = _cli("map", "--map", str(bad), "--episodes", "1")
    assert result.returncode == 2
    assert f"{bad}:2:3: bad character '%'" in result.stderr


def test_a_users_teammate_replaces_the_worlds(tmp_path, monkeypatch):
    from embodied_adhoc.domains.chapter5.teammates import world_with_teammate
    from embodied_adhoc.errors import ConfigError

    (tmp_path / "my_teammates.py").write_text(
        "import numpy as np\n"
        "def frozen(library, model):\n"
        "    policy = np.zeros((library.n_states, 5))\n"
        "    policy[:, 4] = 1.0  # always stays\n"
        "    return policy\n"
        "def broken(library, model):\n"
        "    return np.ones((3, 5))\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    library = build_library("ntu")
    world = world_with_teammate(library, "my_teammates:frozen")
    names = library.state_names
    x = names.index("ar1c2-tr4c4")
    for action in range(5):
        row = world[0].transitions[action][x]
        assert all(names[y].endswith("-tr4c4") for y in row.indices)  # the teammate never moves
    with pytest.raises(ConfigError, match=r"my_teammates:broken: returned shape \(3, 5\)"):
        world_with_teammate(library, "my_teammates:broken")
    with pytest.raises(
        ConfigError, match="unknown teammate of ntu; give one of optimal, random, or MODULE:CALLABLE"
    ):
        world_with_teammate(library, "frozen")
    # named teammates: the optimal one is the library's own (maps), the random one moves uniformly
    optimal = world_with_teammate(library, "optimal")
    assert (optimal[0].transitions[0] != library.pomdps[0].transitions[0]).nnz == 0
    random_world = world_with_teammate(library, "random")
    assert len(random_world[0].transitions[4][x].indices) > 1
    options = {**_options(), "teammate": "my_teammates:frozen"}
    config = SweepConfig("ntu", "abstract", options, ("value-iteration",), episodes=2, seed=1, max_steps=20)
    assert len(run_sweep(config).records) == 2


def test_cli_map_domains_take_a_users_teammate(tmp_path):
    import os

    (tmp_path / "still_teammate.py").write_text(
        "import numpy as np\n"
        "def still(library, model):\n"
        "    policy = np.zeros((library.n_states, 5))\n"
        "    policy[:, 4] = 1.0\n"
        "    return policy\n"
    )
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    result = _cli(
        "ntu", "--agents", "value-iteration,random", "--episodes", "2", "--teammate", "still_teammate:still",
        "--json", env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["config"]["options"]["teammate"] == "still_teammate:still"
    result = _cli("ntu", "--episodes", "1", "--teammate", "nowhere:still", env=env)
    assert result.returncode == 2 and "--teammate 'nowhere:still': no module 'nowhere'" in result.stderr


def test_power_plant_takes_a_world_teammate(tmp_path, monkeypatch):
    import os

    from embodied_adhoc.domains.chapter5.teammates import world_with_teammate
    from embodied_adhoc.errors import ConfigError

    (tmp_path / "plant_humans.py").write_text(
        "import numpy as np\n"
        "def idle(library, model):  # the human always stays (its action 3), in the task's own states\n"
        "    policy = np.zeros((library.mmdps[model].n_states, 4))\n"
        "    policy[:, 3] = 1.0\n"
        "    return policy\n"
        "def padded(library, model):\n"
        "    return np.full((library.n_states, 4), 0.25)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    plant = build_library("power-plant")  # explore (105 states) and clean (97, padded to 105)
    optimal = world_with_teammate(plant, "optimal")  # the library's own human
    assert all(_same_world(w, p) for w, p in zip(optimal, plant.pomdps, strict=True))
    idle = world_with_teammate(plant, "plant_humans:idle")
    assert [w.n_states for w in idle] == [105, 105]
    for m, world in enumerate(idle):
        names = plant.native_pomdps[m].state_names
        for x, name in enumerate(names[:-1]):  # the human's room (h<k>) never changes
            successors = {
                names[y].split("-")[0][2:] for y in world.transitions[3][x].indices if y < len(names) - 1
            }
            assert successors <= {name.split("-")[0][2:]}
        assert not _same_world(world, plant.pomdps[m])
    random_world = world_with_teammate(plant, "random")
    start = int(np.flatnonzero(plant.pomdps[0].initial_belief)[0])
    assert len(random_world[0].transitions[3][start].indices) > len(
        plant.pomdps[0].transitions[3][start].indices
    )
    with pytest.raises(
        ConfigError, match=r"plant_humans:padded: returned shape \(105, 4\) for model 1; expected \(97, 4\)"
    ):
        world_with_teammate(plant, "plant_humans:padded")
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    result = _cli("power-plant", "--help", env=env)
    assert result.returncode == 0 and "test): optimal, random (optimal: the library's human" in " ".join(
        result.stdout.split()
    )
    result = _cli(
        "power-plant", "--agents", "value-iteration", "--episodes", "2", "--teammate", "plant_humans:idle",
        "--json", env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["config"]["options"]["teammate"] == "plant_humans:idle"
    result = _cli("power-plant", "--episodes", "1", "--teammate", "lazy", env=env)
    assert (
        result.returncode == 2
        and "unknown teammate of power-plant; give one of optimal, random" in result.stderr
    )


def test_a_stage_budget_gives_the_same_policy_on_any_load(tmp_path, monkeypatch):
    """The default budget is a number of Perseus stages: a wall clock that jumps 0.5 s at every reading (what a
    solve sees on a heavily loaded machine) changes nothing, where the same clock cuts a wall-clock budget short."""
    import time

    from embodied_adhoc.decision.perseus import PerseusConfig, perseus
    from embodied_adhoc.experiments.domains.chapter5 import SOLVE_STAGES, solver_settings

    library = build_library("gridworld", n_models=1)
    settings = solver_settings(library, {"beliefs": 100, "solve_stages": 8})
    assert settings == {
        "n_beliefs": 100,
        "tolerance": 0.01,
        "max_iterations": 8,
        "time_limit": None,
        "seed": 0,
        "update": "perseus",
    }
    assert solver_settings(library, {})["max_iterations"] == SOLVE_STAGES["gridworld"]
    pomdp = library.pomdps[0]
    idle = perseus(pomdp, PerseusConfig(**settings))
    timed_idle = perseus(pomdp, PerseusConfig(**{**settings, "time_limit": 5.0}))
    real_clock, offset = time.perf_counter, [0.0]

    def loaded_clock() -> float:  # every reading 0.5 s later than the last: a stage here takes ~0.02 s
        offset[0] += 0.5
        return real_clock() + offset[0]

    monkeypatch.setattr(time, "perf_counter", loaded_clock)
    loaded = perseus(pomdp, PerseusConfig(**settings))
    timed_loaded = perseus(pomdp, PerseusConfig(**{**settings, "time_limit": 5.0}))
    monkeypatch.setattr(time, "perf_counter", real_clock)
    assert idle.stats.iterations == loaded.stats.iterations == 8
    assert np.array_equal(idle.alphas, loaded.alphas) and np.array_equal(idle.actions, loaded.actions)
    assert timed_loaded.stats.iterations < timed_idle.stats.iterations  # the clock does reach the solver


def test_policy_cache_key_covers_every_solver_module(tmp_path, monkeypatch):
    from embodied_adhoc.experiments import policy_cache

    names = {path.name for path in policy_cache.solver_sources()}
    assert {"perseus.py", "backup.py", "plan_graph.py", "upper_bound.py", "models.py"} <= names
    copy = tmp_path / "plan_graph.py"
    copy.write_text((ROOT / "embodied_adhoc" / "decision" / "plan_graph.py").read_text())
    monkeypatch.setattr(policy_cache, "solver_sources", lambda: [copy])
    policy_cache._solver_digest.cache_clear()
    before = policy_cache._solver_digest()
    copy.write_text(copy.read_text() + "\n# edited\n")
    policy_cache._solver_digest.cache_clear()
    assert policy_cache._solver_digest() != before
    policy_cache._solver_digest.cache_clear()


def _same_world(first, second) -> bool:
    return all(abs(a - b).max() < 1e-12 for a, b in zip(first.transitions, second.transitions, strict=True))


def test_named_world_teammates_are_the_domains_own_models():
    from embodied_adhoc.domains.chapter5.teammates import DOMAIN_TEAMMATES, world_with_teammate
    from embodied_adhoc.errors import ConfigError

    both = build_library("pursuit-teammate")  # models: greedy and aware, same capture configuration
    assert set(both.teammates) == set(DOMAIN_TEAMMATES["pursuit-teammate"])
    aware = world_with_teammate(both, "aware")
    greedy = world_with_teammate(both, "greedy")
    assert _same_world(aware[0], both.pomdps[1]) and _same_world(greedy[1], both.pomdps[0])
    assert not _same_world(aware[0], both.pomdps[0])
    cooks = build_library("overcooked")
    assert set(cooks.teammates) == set(DOMAIN_TEAMMATES["overcooked"])
    for k, name in enumerate(cooks.task_names):  # each named cook is that model's, in every model's world
        world = world_with_teammate(cooks, name)
        assert _same_world(world[3 - k], cooks.pomdps[k])
    grid = build_library("gridworld", n_models=3)
    assert set(grid.teammates) == set(DOMAIN_TEAMMATES["gridworld"])
    small = grid.subset([2, 0])
    assert _same_world(world_with_teammate(small, "greedy")[0], grid.pomdps[2])
    assert build_library("ntu").teammates == {}
    with pytest.raises(
        ConfigError, match="unknown teammate of overcooked; give one of optimal, upper, lower, random"
    ):
        world_with_teammate(cooks, "stubborn")


def test_cli_lists_and_refuses_teammate_names(tmp_path):
    import os

    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    result = _cli("pursuit-task", "--help", env=env)
    assert result.returncode == 0 and "greedy, aware, optimal, random" in " ".join(result.stdout.split())
    result = _cli("pursuit-task", "--episodes", "1", "--teammate", "lazy", env=env)
    assert result.returncode == 2
    assert "unknown teammate of pursuit-task; give one of greedy, aware, optimal, random" in result.stderr


def test_a_blind_perseus_policy_is_refused_and_not_cached(private_cache, monkeypatch):
    from embodied_adhoc.decision.policy import AlphaVectorPolicy, SolverStats
    from embodied_adhoc.errors import ConfigError
    from embodied_adhoc.experiments import policy_cache
    from embodied_adhoc.experiments.domains.chapter5 import Chapter5Session

    solved = []

    def timed_out(pomdp, config):  # what Perseus returns when its limit falls before the first stage
        solved.append(config.time_limit)
        stats = SolverStats(
            "perseus", iterations=0, seconds=config.time_limit, converged=False, residual=np.inf
        )
        return AlphaVectorPolicy(np.zeros((1, pomdp.n_states)), np.zeros(1, dtype=np.int64), stats=stats)

    real = __import__("embodied_adhoc.decision.perseus", fromlist=["perseus"]).perseus
    monkeypatch.setattr("embodied_adhoc.decision.perseus.perseus", timed_out)
    session = Chapter5Session(
        "panic-buttons",
        {**_options(cache=True), "solve_seconds": 5.0, "library": {"size": 3, "teammate": "optimal"}},
    )
    with pytest.raises(ConfigError, match=r"before its first backup for model\(s\) .*raise --solve-seconds"):
        session.policies()
    assert len(solved) == 3 and not list(private_cache.rglob("*.npz"))
    monkeypatch.setattr("embodied_adhoc.decision.perseus.perseus", real)  # one backup at least: a policy
    assert not policy_cache.is_blind(solve_cached(session.library.pomdps[0], {"n_beliefs": 20, "seed": 0})[0])


def test_cli_table_shows_the_return_and_the_timing(tmp_path):
    import os

    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    path = _corridor(tmp_path)
    result = _cli("map", "--map", str(path), "--agents", "value-iteration,random", "--episodes", "3", env=env)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    header = next(k for k, line in enumerate(lines) if "return mean ± sd" in line)
    assert "return 95% CI (bootstrap)" in lines[header]
    optimal = next(line for line in lines[header:] if line.strip().startswith("value-iteration"))
    assert float(optimal.split()[2]) > 0  # the greedy agent reaches the +100 in a corridor
    assert any(line.startswith("library built in") for line in lines)
