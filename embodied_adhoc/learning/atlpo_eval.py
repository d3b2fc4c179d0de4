"""Steps to finish of the chapter-6 agents in each library environment (thesis section 6.2.5), on the single
grid env (the same one the trial runner uses), with the classifier's posterior recorded per step.

Agents: ``original`` (the team's own policy in the ad hoc seat, full state: the thesis's *original teammate*),
``known`` (the library member of the true environment, i.e. model-free RL that knows task and team), ``mf-all``
(one PPO policy trained on all the set's environments together, only when given), ``atlpo-mf``
(:class:`~embodied_adhoc.learning.atlpo.AtlpoAgent`) and ``random``. An episode that does not finish counts its
step cap. Episodes are seeded by ``(seed, environment, episode)`` and shared by every agent.
"""

from __future__ import annotations

import gymnasium
import numpy as np
import torch

from embodied_adhoc.decision.agents.selection import draw_action
from embodied_adhoc.domains.grid_rules_team import team_actions
from embodied_adhoc.learning.atlpo import AtlpoAgent, PolicyLibrary
from embodied_adhoc.learning.classifier import RecurrentBayesianClassifier
from embodied_adhoc.learning.networks import ActorCritic
from embodied_adhoc.learning.vector_grid import GRID_IDS

AGENTS = ("original", "known", "mf-all", "atlpo-mf", "random")


def play(
    library: PolicyLibrary,
    classifier: RecurrentBayesianClassifier,
    agent: str,
    k: int,
    seed: int,
    max_steps: int,
    generalist: ActorCritic | None = None,
) -> tuple[int, bool, list[float]]:
    """One episode of ``agent`` in library environment ``k``: (steps, finished, posterior of the true
    environment after each step, for ATLPO)."""
    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.envs.grid_world_env import state_from_dict

    env = gymnasium.make(GRID_IDS[library.domain], max_episode_steps=max_steps, **library.env_for(k))
    observation, info = env.reset(seed=seed)
    core = env.unwrapped.core
    rng = np.random.default_rng(seed + 1)
    learned = None
    if agent in ("known", "atlpo-mf"):
        learned = AtlpoAgent(library, classifier, known=k if agent == "known" else None)
        learned.reset(rng)
        learned.start(observation)
    beliefs = []
    for step in range(1, max_steps + 1):
        if agent == "random":
            action = int(rng.integers(5))
        elif agent == "mf-all":
            with torch.no_grad():
                probabilities = generalist.action_distribution(torch.as_tensor(observation)[None])[0]
            action = draw_action(probabilities.double().numpy(), rng, False)
        elif agent == "original":
            state = state_from_dict(info["state"], core.rules)
            action = int(team_actions(core.rules, state, core.task, core.teams[info["team"]], rng, [0])[0])
        else:
            action = learned.act()
        observation, _, terminated, truncated, info = env.step(action)
        if learned is not None:
            learned.observe(action, observation)
            beliefs.append(float(learned.library_posterior[k]))
        if terminated or truncated:
            env.close()
            return step, bool(terminated), beliefs
    env.close()
    return max_steps, False, beliefs


def evaluate(
    library: PolicyLibrary,
    classifier: RecurrentBayesianClassifier,
    episodes: int,
    seed: int,
    max_steps: int = 200,
    agents: tuple[str, ...] = AGENTS,
    generalist: ActorCritic | None = None,
) -> dict:
    """Per agent: steps of every episode (environment-major), finished flags; for ATLPO the true environment's
    posterior per step (mean over episodes that reach the step)."""
    agents = tuple(name for name in agents if name != "mf-all" or generalist is not None)
    results = {name: {"steps": [], "finished": []} for name in agents}
    beliefs: list[list[float]] = []
    for k in range(len(library.policies)):
        for episode in range(episodes):
            episode_seed = seed * 1_000_003 + k * 10_007 + episode
            for name in agents:
                steps, finished, trace = play(
                    library, classifier, name, k, episode_seed, max_steps, generalist
                )
                results[name]["steps"].append(steps)
                results[name]["finished"].append(finished)
                if name == "atlpo-mf":
                    beliefs.append(trace)
    longest = max((len(b) for b in beliefs), default=0)
    results["true_posterior_per_step"] = [
        float(np.mean([b[t] for b in beliefs if len(b) > t])) for t in range(longest)
    ]
    return results
