"""A tiny but genuine trial domain for the runner's tests (no dependency on the lab models).

Task k in {0, 1}: the team finishes after the robot has taken action k three times. Every step emits a noisy
reading of the task (correct w.p. 0.8) as observation index 0/1. Agents: ``bayes`` (posterior over tasks, acts on
its argmax), ``known-task``, ``oracle`` (observes the state = progress count), ``random``.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from embodied_adhoc.decision.agents.base import AgentBase

ACCURACY = 0.8


class GuessEnv(gym.Env):
    def __init__(self):
        self.action_space = gym.spaces.Discrete(2)
        self.observation_space = gym.spaces.Discrete(2)
        self.task = 0
        self.progress = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.task = int(options["task"])
        self.progress = 0
        return 0, {"state": self.progress, "observation_index": 0}

    def step(self, action):
        if action == self.task:
            self.progress += 1
        reading = self.task if self.np_random.random() < ACCURACY else 1 - self.task
        done = self.progress >= 3
        return reading, -1.0, done, False, {"state": self.progress, "observation_index": int(reading)}

    def privileged_state(self):
        return self.progress


class BayesAgent(AgentBase):
    observes_state = False

    def __init__(self, name, known_task=None):
        self.name = name
        self.known_task = known_task
        self.posterior = np.full(2, 0.5)

    def reset(self, rng, state=None):
        assert state is None
        self.rng = rng
        self.posterior = np.full(2, 0.5)
        if self.known_task is not None:
            self.posterior = np.eye(2)[self.known_task]

    def act(self):
        return int(np.argmax(self.posterior))

    def observe(self, action, observation, state=None):
        assert state is None
        if self.known_task is None:
            likelihood = np.where(np.arange(2) == observation, ACCURACY, 1 - ACCURACY)
            self.posterior = self.posterior * likelihood / (self.posterior @ likelihood)

    @property
    def task_posterior(self):
        return self.posterior


class RandomAgent(AgentBase):
    observes_state = False
    task_posterior = None

    def __init__(self, name):
        self.name = name

    def reset(self, rng, state=None):
        self.rng = rng

    def act(self):
        return int(self.rng.integers(2))

    def observe(self, action, observation, state=None):
        pass


class OracleAgent(RandomAgent):
    observes_state = True

    def __init__(self, name, task):
        super().__init__(name)
        self.task = task
        self.states = []

    def reset(self, rng, state=None):
        assert state == 0
        self.states = [state]

    def act(self):
        return self.task

    def observe(self, action, observation, state=None):
        assert state is not None
        self.states.append(state)


class Session:
    task_names = ("zero", "one")

    def make_env(self, max_steps):
        return GuessEnv()

    def reset_options(self, spec):
        return {"task": spec["task"]}

    def make_agent(self, name, spec, seed):
        if name == "bayes":
            return BayesAgent(name)
        if name == "known-task":
            return BayesAgent(name, known_task=spec["task"])
        if name == "oracle":
            return OracleAgent(name, spec["task"])
        return RandomAgent(name)

    def observation_index(self, observation):
        return int(observation)


class GuessDomain:
    name = "guess"
    description = "test domain: find which of two actions finishes the task"
    backends = ("abstract", "twin")  # twin: the same env, to test backend comparisons
    agent_names = ("bayes", "known-task", "oracle", "random")
    default_agents = ("bayes", "known-task", "oracle", "random")

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--task", type=int, choices=(0, 1), default=None)

    def options_from_args(self, args):
        return {"task": args.task}

    def episode_spec(self, options, rng):
        task = options.get("task")
        return {"task": int(rng.integers(2)) if task is None else int(task)}

    def open_session(self, backend, options):
        return Session()


DOMAIN = GuessDomain()
