"""The one episode loop: observers see every hook in order; termination, truncation and the cap are reported."""

import numpy as np

from embodied_adhoc.episodes.loop import EpisodeObserver, run_episode_loop


class CountdownEnv:
    """Terminates when the agent has taken action 1 ``needed`` times; truncates at ``limit`` steps."""

    def __init__(self, needed: int, limit: int = 10**6):
        self.needed, self.limit = needed, limit

    def reset(self, seed=None, options=None):
        self.ones = self.steps = 0
        self.seed, self.options = seed, options
        return 0, {"state": 0}

    def privileged_state(self):
        return self.ones

    def step(self, action):
        self.steps += 1
        self.ones += action == 1
        info = {"state": self.ones, "observation_index": 10 + self.steps}
        return self.steps, -1.0, self.ones >= self.needed, self.steps >= self.limit, info


class AlternatingAgent:
    observes_state = True
    observes_raw = observes_reward = False

    def start(self, observation):
        pass

    def reset(self, rng, state=None):
        self.turn, self.states, self.observed = 0, [state], []
        self.task_posterior = np.array([0.5, 0.5])

    def act(self):
        self.turn += 1
        return self.turn % 2

    def observe(self, action, observation, state=None):
        self.observed.append((action, observation))
        self.states.append(state)
        self.task_posterior = np.array([0.5, 0.5]) + 0.1 * len(self.observed) * np.array([1, -1])


class Log(EpisodeObserver):
    def __init__(self):
        self.events = []

    def episode_started(self, info, task_posterior):
        self.events.append(("start", tuple(task_posterior)))

    def step_started(self, step):
        self.events.append(("step", step))

    def action_chosen(self, step, action):
        self.events.append(("action", step, action))

    def step_finished(self, record):
        self.events.append(
            ("done", record.step, record.observation_index, record.terminated, record.truncated)
        )

    def episode_finished(self, trace):
        self.events.append(("end", trace.steps, trace.success, trace.truncated))


def run(env, max_steps, observers=()):
    agent = AlternatingAgent()
    trace = run_episode_loop(
        env,
        agent,
        env_seed=7,
        agent_rng=np.random.default_rng(0),
        reset_options={"task": 1},
        max_steps=max_steps,
        observation_index=lambda observation: 10 + observation,
        observers=observers,
    )
    return trace, agent


def test_observers_see_every_hook_in_order_and_termination_is_success():
    log = Log()
    env = CountdownEnv(needed=2)
    trace, agent = run(env, max_steps=10, observers=[log])
    assert env.seed == 7 and env.options == {"task": 1}
    assert trace.actions == [1, 0, 1] and trace.observations == [11, 12, 13] and trace.rewards == [-1.0] * 3
    assert trace.success and not trace.truncated and trace.steps == 3
    assert agent.observed == [(1, 11), (0, 12), (1, 13)]
    assert agent.states == [0, 1, 1, 2]  # observes_state agents get info["state"] at reset and every step
    history = trace.posterior_history()
    assert history.shape == (4, 2) and np.allclose(history[-1], [0.8, 0.2])
    assert log.events == [
        ("start", (0.5, 0.5)),
        ("step", 1), ("action", 1, 1), ("done", 1, 11, False, False),
        ("step", 2), ("action", 2, 0), ("done", 2, 12, False, False),
        ("step", 3), ("action", 3, 1), ("done", 3, 13, True, False),
        ("end", 3, True, False),
    ]  # fmt: skip


def test_env_truncation_and_the_loop_cap_are_not_success():
    trace, _ = run(CountdownEnv(needed=99, limit=4), max_steps=10)
    assert trace.steps == 4 and trace.truncated and not trace.success
    trace, _ = run(CountdownEnv(needed=99), max_steps=5)
    assert trace.steps == 5 and trace.truncated and not trace.success
