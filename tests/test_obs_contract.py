"""The observation contract: an agent's observation is the env's ``obs``; ``info`` is ground truth and diagnostics.

Every shipped agent of every trial domain runs one episode twice, once on the env as it is and once on the env with
``info`` replaced by an empty dict; the privileged agents (``observes_state``) get the state through the env's
``privileged_state()`` both times, and they are exactly the agents the tables mark as privileged. Identical
trajectories (actions, observation indices, rewards, task posteriors) mean that nothing an agent did depended on
``info``. Together the cases cover every registered env id.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from embodied_adhoc.envs.registry import ENV_SPECS
from embodied_adhoc.experiments import seeding
from embodied_adhoc.experiments.executors import open_session
from embodied_adhoc.experiments.registry import build_agent, get_trial_domain
from embodied_adhoc.experiments.trial import TrialJob, run_trial


class EmptyInfo:
    """``env`` with every ``info`` replaced by ``{}``; ``unwrapped`` (the privileged channel) is the env's own."""

    def __init__(self, env) -> None:
        self.env = env

    @property
    def unwrapped(self):
        return getattr(self.env, "unwrapped", self.env)

    def reset(self, **kwargs):
        observation, _ = self.env.reset(**kwargs)
        return observation, {}

    def step(self, action):
        observation, reward, terminated, truncated, _ = self.env.step(action)
        return observation, reward, terminated, truncated, {}


# (domain, trials flags, backends, step cap): every shipped agent of the domain runs on each backend
CASES = [
    ("toxic-waste", [], ("abstract", "mujoco"), {"abstract": 30, "mujoco": 2}),
    ("foraging", [], ("abstract", "mujoco"), {"abstract": 10, "mujoco": 2}),
    ("pursuit", [], ("abstract", "mujoco"), {"abstract": 20, "mujoco": 2}),
    ("pursuit", ["--pairs", "--rules", "grid"], ("abstract", "mujoco"), {"abstract": 20, "mujoco": 2}),
    (
        "pursuit",
        ["--pairs", "--rules", "pomdp", "--agents", "hotspot"],
        ("abstract", "mujoco"),
        {"abstract": 20, "mujoco": 2},
    ),
    ("pursuit4", ["--learn-steps", "0"], ("abstract", "mujoco"), {"abstract": 20, "mujoco": 2}),
    ("gridworld", [], ("abstract",), {"abstract": 30}),
    ("pursuit-task", [], ("abstract",), {"abstract": 30}),  # where the library-free agents ship for chapter 5
]


def _options(name: str, flags: list[str]):
    from embodied_adhoc.commands.trials import _add_common_arguments

    domain = get_trial_domain(name)
    parser = argparse.ArgumentParser()
    _add_common_arguments(parser, domain)
    domain.add_arguments(parser)
    return domain, domain.options_from_args(parser.parse_args(flags))


def _agents(domain, options) -> tuple[str, ...]:
    if domain.name == "pursuit":  # the grid rules offer the grid agents, the POMDP rules the decision agents
        from embodied_adhoc.experiments.domains.foraging import GridTrialDomain
        from embodied_adhoc.experiments.domains.pursuit_pairs import POMDP_AGENTS

        if options.get("rules") == "pomdp":
            return POMDP_AGENTS + ("random",)
        if options.get("pairs"):  # the shipped ATLPO library is trained for four predators
            return ("original", "random")
        return tuple(name for name in GridTrialDomain.agent_names if _shipped(name, domain.name))
    return tuple(name for name in domain.agent_names if _shipped(name, domain.name)) + _learned_plugins(
        domain.name
    )


# The library-free agents are trained per domain; one without shipped weights is the user's to train.
_LEARNED = {
    "ppo-generalist": "embodied_adhoc.learning.generalist",
    "liam": "embodied_adhoc.learning.liam",
    "meliba": "embodied_adhoc.learning.meliba",
}


def _shipped(agent: str, domain: str) -> bool:
    """Whether the package ships what ``agent`` needs on ``domain`` (``train AGENT --domain D`` makes the rest)."""
    if agent not in _LEARNED:
        return True
    import importlib

    from embodied_adhoc.errors import ConfigError

    try:
        return importlib.import_module(_LEARNED[agent]).shipped_weights(domain).is_file()
    except ConfigError:  # none shipped for this domain
        return False


def _learned_plugins(domain: str) -> tuple[str, ...]:
    """The library-free agents on the lab and pursuit-task: plug-ins (``MODULE:plugin``) where weights ship."""
    from embodied_adhoc.learning.index_domains import INDEX_DOMAINS

    if domain not in INDEX_DOMAINS:
        return ()
    return tuple(f"{module}:plugin" for agent, module in _LEARNED.items() if _shipped(agent, domain))


def _trajectory(session, env, job):
    result = run_trial(session, env, job)
    return result.actions, result.observations, result.rewards, result.success, result.posteriors


@pytest.mark.parametrize(
    ("name", "flags", "backend"),
    [(name, flags, backend) for name, flags, backends, _ in CASES for backend in backends],
    ids=lambda value: value if isinstance(value, str) else " ".join(value) or "-",
)
def test_every_shipped_agent_acts_the_same_without_info(name, flags, backend, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("MUJOCO_GL", "egl")
    if backend == "mujoco":
        from embodied_adhoc.gl import choose_gl_platform

        choose_gl_platform()
    from embodied_adhoc.decision.agents import factory

    # the lab's ATPO on a small Perseus budget too (the factory reads these settings when it solves)
    monkeypatch.setattr(
        factory, "DEFAULT_PERSEUS", {**factory.DEFAULT_PERSEUS, "n_beliefs": 64, "max_iterations": 3}
    )
    domain, options = _options(name, flags)
    cap = dict(next(c[3] for c in CASES if c[0] == name and c[1] == flags))[backend]
    session = open_session(domain.name, backend, options)
    if hasattr(session, "atpo_policies") or hasattr(session, "policies"):
        # Perseus on a small budget: which policies ATPO follows does not matter here, only that it follows them
        # the same way with and without info
        from embodied_adhoc.decision.perseus import PerseusConfig, perseus

        config = PerseusConfig(n_beliefs=64, max_iterations=3, update="perseus", seed=0)
        policies = tuple(perseus(pomdp, config) for pomdp in session.library.pomdps)
        if hasattr(session, "atpo_policies"):  # the pursuit POMDP
            monkeypatch.setattr(session, "atpo_policies", lambda: policies)
        else:  # chapter 5
            monkeypatch.setattr(session, "_policies", policies)
    # a trial's diagnostics (fault counts) read info, as evaluation may: switched off, the agents' part remains
    monkeypatch.setattr(session, "trial_extras", None, raising=False)
    env = session.make_env(cap)
    spec = domain.episode_spec(options, seeding.episode_rng(3, 0))
    try:
        for agent in _agents(domain, options):
            job = TrialJob(domain.name, backend, options, 3, cap, agent, 0, spec)
            built = build_agent(domain, session, agent, spec, 0)
            declared = agent in getattr(domain, "privileged_agents", ())
            assert bool(built.observes_state) == declared, f"{agent}: the tables' privileged mark is wrong"
            a = _trajectory(session, env, job)
            b = _trajectory(session, EmptyInfo(env), job)
            assert len(a[0]) >= 1, agent
            assert a[:4] == b[:4], f"{name} {backend} {agent}: the trajectory depends on info"
            assert (a[4] is None) == (b[4] is None) and (a[4] is None or np.array_equal(a[4], b[4])), agent
    finally:
        env.close()


def test_the_cases_cover_every_registered_env_id():
    covered = set()
    for name, flags, backends, _ in CASES:
        domain, options = _options(name, flags)
        for backend in backends:
            chapter5 = name in ("gridworld", "pursuit-task")  # their world is the model itself, no env id
            covered.add(None if chapter5 else open_session(domain.name, backend, options).env_id)
    assert {spec.id for spec in ENV_SPECS} <= covered
