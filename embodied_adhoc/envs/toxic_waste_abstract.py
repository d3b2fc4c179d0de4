"""The abstract toxic-waste lab (HOTSPOT, thesis section 7.1) as a fast Gymnasium env."""

from __future__ import annotations

import gymnasium
from gymnasium import spaces

from embodied_adhoc import checks
from embodied_adhoc.domains.lab import LAB_PARAMETERS, LabConfig, apply_step, library_from_config
from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.lab_picture import LabPicture

__all__ = ["ToxicWasteAbstractEnv"]


class ToxicWasteAbstractEnv(gymnasium.Env):
    """A robot container helps a human drop waste balls into it, on the lab's topological map.

    ## Description
    Five areas (0 door, 1 open space, 2 robot station, 3 single workbench, 4 double workbench; passages 0-1, 1-2,
    1-3, 3-4). A task places the balls (default tasks: nodes [0, 1, 2] and [1, 2, 3]). The human
    (``domains.lab_human``) knows the task, walks to the nearest ball on the ground, picks it up, and waits
    holding it until the robot is at the same node and stays or asks; then the ball goes into the container.
    With probability ``human_epsilon`` a human move or pick fails. The robot knows neither the task nor where
    the human is. Dynamics, observations and reward are those of ``domains.lab`` (sampled from the rules).

    ## Action space
    ``Discrete(5)`` (``Discrete(4)`` without communication):

    | action | meaning |
    |---|---|
    | 0, 1, 2 | move to the 1st / 2nd / 3rd lowest-index neighbour (beyond the degree: the lowest) |
    | 3 | stay (hands a held ball over when co-located with the human) |
    | 4 | locate human: ask where the human is (also hands over); absent without communication |

    ## Observation space
    ``MultiDiscrete([6, 6, 2])`` = ``[robot node, human node, rfid]`` with 5 = unknown/none
    (``domains.lab_observations.LabObservation``): robot node from dead reckoning, right with probability
    ``robot_node_accuracy`` else unknown; human node after "locate human" from the speech confusion matrix
    ("failed" = none), or without communication the robot's node when co-located; rfid = 1 when a ball entered
    the container in this step (missed with probability ``rfid_miss``). ``info["observation_index"]`` is the
    flat index the agents consume.

    ## Rewards
    Before each step: -1 per ball on the ground, -2 per ball held, 0 per ball disposed.

    ## Episode end
    Terminated when every ball is in the container; truncated by the registered ``TimeLimit`` (100 steps, the
    thesis's cap; ``gymnasium.make(id, max_episode_steps=N)`` changes it). ``step`` after the end raises
    (``envs.contract``).

    ## Arguments
    ``task`` (fixed task index, default: drawn uniformly at each reset), ``render_mode`` (None or "rgb_array":
    a picture of the graph, robot, human and balls; "ansi": one line of text) and the lab parameters of
    ``domains.lab.LabConfig``, which holds their defaults: ``tasks`` (ball placements), ``human_epsilon``,
    ``communication``, ``confusion`` ("measured", "thesis" or a JSON path), ``robot_node_accuracy``,
    ``rfid_miss``, ``graph`` (``LabGraph``), ``reward``, ``discount``; ``human`` (the world's human teammate:
    ``"scripted"``, the default, or a plug-in; interface in ``envs.lab_humans``; the agents' models are not told).
    ``reset(options={"task": k, "robot_node": i, "human_node": j})`` fixes the episode's start (default:
    uniform nodes, all balls on the ground).

    ## Info (ground truth, for evaluation only)
    ``state`` (shared state index of the lab library), ``task``, ``robot_node``, ``human_node``,
    ``ball_status`` (0 ground, 1 held, 2 disposed), ``disposed_this_step``, ``observation_index``.

    ## Version history
    v0: first version.
    """

    metadata = {"render_modes": ["rgb_array", "ansi"], "render_fps": 4}

    @contract.keywords(*LAB_PARAMETERS)
    def __init__(self, task: int | None = None, render_mode: str | None = None, human=None, **lab) -> None:
        from embodied_adhoc.envs.lab_humans import lab_humans

        self.library = library_from_config(LabConfig.from_kwargs(type(self).__name__, lab))
        self._humans = lab_humans(self.library, human)  # the world's human; the agents' models keep theirs
        self.task = None if task is None else checks.integer("task", task, 0, self.library.n_tasks - 1)
        self.render_mode = contract.render_mode(render_mode, ("rgb_array", "ansi"))
        n = self.library.graph.n_nodes
        self.action_space = spaces.Discrete(self.library.n_actions)
        self.observation_space = spaces.MultiDiscrete([n + 1, n + 1, 2])
        reward = self.library.config.reward
        self._reward_table = (reward.ground, reward.held, reward.disposed)
        self._robot = self._human = self._task = self._steps = 0
        self._status: tuple[int, ...] = (GROUND,) * len(self.library.tasks[0])
        self._episode = contract.EpisodeGate(type(self).__name__)
        self._picture: LabPicture | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        lib = self.library
        self._task, self._robot, self._human = lib.episode_start(options, self.task, self.np_random)
        self._status = (GROUND,) * len(lib.tasks[0])
        self._steps = 0
        self._episode.open()
        return self._observe(lib.stay_action, False)

    def step(self, action):
        self._episode.check()
        action = contract.action(
            action, self.library.n_actions, "see the action table of the env's docstring"
        )
        reward = float(sum(self._reward_table[s] for s in self._status))
        human = self._humans[self._task].step(self.np_random, self._human, self._status)
        self._robot, self._human, self._status, disposed = apply_step(
            self.library.graph, self._robot, self._human, self._status, action, human
        )
        self._steps += 1
        observation, info = self._observe(action, disposed)
        terminated = all(s == DISPOSED for s in self._status)
        self._episode.close_if(terminated)
        return observation, reward, terminated, False, info

    def _observe(self, action: int, disposed: bool):
        model = self.library.observation_model
        said, asked = self._human, action
        answer = getattr(self._humans[self._task], "answer", None)
        if answer is not None and action == model.locate_action:
            # A human with an answer of its own (envs.lab_humans) says a node, or nothing: the speech channel then
            # carries what was said, and no reply reads as a question never asked.
            said = answer(self.np_random, self._human)
            if said is None:
                said, asked = self._human, self.library.stay_action
        index = model.sample_index(self.np_random, self._robot, said, disposed, asked)
        info = {
            "state": self.library.states.fast_index(self._robot, self._human, self._status, disposed),
            "task": self._task,
            "robot_node": self._robot,
            "human_node": self._human,
            "ball_status": self._status,
            "disposed_this_step": disposed,
            "observation_index": index,
        }
        self._state_index = info["state"]
        return model.vector(index), info

    def privileged_state(self) -> int:
        """The true state, as ``info["state"]`` holds it: the one channel through which the episode loop gives it to
        privileged agents (``observes_state``); agents never read ``info``."""
        return self._state_index

    def render(self):
        if self.render_mode == "rgb_array":
            if self._picture is None:
                self._picture = LabPicture(self.library.graph)
            return self._picture.draw(self._robot, self._human, self.library.tasks[self._task], self._status)
        if self.render_mode != "ansi":
            return None
        names = {0: "ground", 1: "held", 2: "disposed"}
        balls = ", ".join(
            f"ball {i} at {self.library.tasks[self._task][i]}: {names[s]}" for i, s in enumerate(self._status)
        )
        return (
            f"step {self._steps} task {self._task}: robot at {self._robot}, human at {self._human}; {balls}"
        )
