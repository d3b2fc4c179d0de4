"""The toxic-waste (HOTSPOT lab) trial domain: ``embodied-adhoc trials toxic-waste --backend abstract|mujoco``.

Episode spec (drawn once per episode from ``(seed, episode)``, shared by every agent): ``task`` uniform over the
task library (or fixed by ``--task``; the draw is made either way, so start nodes do not depend on ``--task``),
``robot_node`` and ``human_node`` uniform over the lab's nodes (the models' initial belief: uniform over the 25
node pairs, all balls on the ground).

Backends (same kwargs, same ``reset`` options, same observation encoding):

* ``abstract``: ``EmbodiedAdhoc/ToxicWasteAbstract-v0`` (the tabular simulator);
* ``mujoco``: ``EmbodiedAdhoc/ToxicWaste-v0`` (the physics env). What the runner needs of a backend's env:
  that its id is registered, accepts the kwargs ``tasks``, ``human_epsilon``, ``communication``,
  ``confusion`` (the lab parameters of ``domains.lab.LabConfig``), is capped by gymnasium's ``TimeLimit`` (set to
  the runner's ``--max-steps``), takes ``reset(seed=..., options={"task", "robot_node", "human_node"})``, returns
  the :class:`LabObservation` vector as its observation (the agents' index is decoded from it alone) and offers
  ``privileged_state()`` (index in the library's shared state space, for the agents that observe the state).

Agents come from ``embodied_adhoc.decision.agents.factory.make_agent``; only ``known-task`` and ``oracle`` are
given the true task (at construction), as their definitions require.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning import LEARNED_AGENTS

ENV_IDS = {"abstract": "EmbodiedAdhoc/ToxicWasteAbstract-v0", "mujoco": "EmbodiedAdhoc/ToxicWaste-v0"}
FAULTS = {
    # option name: (physics env kwarg, upper bound, help)
    "wheel_slip": ("wheel_slip", None, "per-episode wheel-radius error, relative std (default 0.0005)"),
    "encoder_noise": ("encoder_noise", None, "encoder noise, rad^0.5 (default 0.002)"),
    "rfid_miss": (
        "reader_miss",
        1.0,
        "probability that the RFID reader misses a ball (the agents' model is told, unless --model-rfid-miss)",
    ),
    "lidar_noise": ("lidar_noise", None, "lidar range noise std in metres (default 0.015)"),
    "lidar_dropout": ("lidar_dropout", 1.0, "probability that a lidar beam returns nothing (1 = dead lidar)"),
    "speech_failure": (
        "speech_failure",
        1.0,
        "probability that the human's reply is lost (the model is not told)",
    ),
}
"""Sensor and actuator faults of the physics lab (``--wheel-slip`` ...). The agents' model is told only the RFID miss
rate: it is the lab parameter ``rfid_miss`` of their observation model (``--model-rfid-miss`` sets it apart)."""


def add_fault_arguments(parser) -> None:
    """The fault options and the localisation switches, shared by ``run toxic-waste`` and ``trials toxic-waste``."""
    for name, (_, _, text) in FAULTS.items():
        parser.add_argument(f"--{name.replace('_', '-')}", type=float, default=None, metavar="X", help=text)
    parser.add_argument(
        "--model-rfid-miss",
        type=float,
        default=None,
        metavar="P",
        help="the RFID miss probability of the agents' observation model (default: --rfid-miss, else 0)",
    )
    parser.add_argument(
        "--no-localisation",
        action="store_true",
        help="drive and read the robot's area on wheel odometry alone (no lidar Monte Carlo localisation)",
    )
    parser.add_argument(
        "--localisation-model",
        default=None,
        metavar="measured|PATH",
        help="the agents' robot-node observation model: the localiser's measured confusion (default: the "
        "thesis's 0.99 accuracy)",
    )


def fault_options(args: argparse.Namespace) -> dict:
    """The fault values given on the command line, checked (only those given)."""
    faults = {}
    for name, (_, high, _) in FAULTS.items():
        value = getattr(args, name)
        if value is None:
            continue
        if not (value >= 0.0 and (high is None or value <= high)) or value != value:
            bound = f"[0, {high}]" if high is not None else ">= 0"
            raise ConfigError(f"--{name.replace('_', '-')} {value}: must be {bound}")
        faults[name] = float(value)
    return faults


def fault_env_kwargs(options: dict) -> dict:
    """The physics env's kwargs for the faults and localisation switch in ``options``."""
    kwargs = {FAULTS[name][0]: value for name, value in options.get("faults", {}).items()}
    if "model_rfid_miss" in options:  # the model's rate is a lab kwarg; the reader keeps its own
        kwargs.setdefault("reader_miss", 0.0)
    if not options.get("localisation", True):
        kwargs["localisation"] = False
    return kwargs


def fault_columns() -> tuple[str, ...]:
    """The per-trial CSV columns of the physics env's fault counts: ``fault_<name>`` for a fault event,
    ``event_<name>`` for what it is counted out of (``envs.toxic_waste.FAULT_COUNTS``)."""
    from embodied_adhoc.envs.toxic_waste import FAULT_COUNTS

    return tuple(f"{kind}_{name}" for name, (kind, _) in FAULT_COUNTS.items())


CAP_COLUMNS = ("cap_reason", "cap_detail")
"""Per-trial columns of an episode that hit the step cap: the uninformative observation's code and the sentence."""


def cap_reason(actions, faults: dict, action_names, capped: bool) -> tuple[str, str]:
    """Why an episode that hit the step cap did not finish: ``(code, sentence)``, ``("", "")`` if not capped.

    The sentence names the action chosen most often and every observation that stayed uninformative, e.g.
    "cap reached: 'locate human' chosen 96/100 steps; RFID missed 2 of 3 reads". The code is ``rfid_missed`` after
    any missed read (the reader reads a ball once: the model never learns that it went in), else the observation
    uninformative most often relative to its readings (``reply_lost``, ``no_location``, ``robot_node_unknown``,
    ``blocked``; ties in this order; a reply or a reading can come again), or ``no_fault`` when none failed.
    """
    if not capped:
        return "", ""
    parts = []
    if len(actions):
        counts = np.bincount(np.asarray(actions, dtype=int), minlength=len(action_names))
        top = int(np.argmax(counts))
        parts.append(f"'{action_names[top]}' chosen {int(counts[top])}/{len(actions)} steps")
    lost = faults.get("replies_lost", 0)
    channels = (
        ("rfid_missed", "rfid_misses", "rfid_reads", "RFID missed {} of {} reads"),
        (
            "reply_lost" if lost else "no_location",
            "replies_no_location",
            "replies",
            "no location heard in {} of {} replies" + (f" ({lost} lost)" if lost else ""),
        ),
        (
            "robot_node_unknown",
            "robot_node_unknown",
            "robot_node_readings",
            "robot node unknown in {} of {} readings",
        ),
        ("blocked", "blocked_moves", "moves", "blocked in {} of {} moves"),
    )
    code, worst = "no_fault", 0.0
    for name, bad_key, total_key, text in channels:
        bad, total = faults.get(bad_key, 0), faults.get(total_key, 0)
        if bad and total:
            parts.append(text.format(bad, total))
            share = math.inf if name == "rfid_missed" else bad / total
            if share > worst:
                code, worst = name, share
    if faults.get("relocalisations"):
        parts.append(f"{faults['relocalisations']} re-localisation(s)")
    if code == "no_fault":
        parts.append("every observation informative")
    return code, "cap reached: " + "; ".join(parts)


def fault_line(faults: dict) -> str:
    """One line of an episode's fault counts (``info["faults"]``) for a text summary."""
    return (
        f"RFID missed {faults['rfid_misses']}/{faults['rfid_reads']} reads; replies lost {faults['replies_lost']}, "
        f"no location {faults['replies_no_location']}/{faults['replies']}; lidar dropped "
        f"{faults['lidar_dropped_beams']}/{faults['lidar_beams']} beams; wheel slip {faults['wheel_slip_m']:.3f} m, "
        f"encoder noise {faults['encoder_noise_m']:.3f} m; {faults['relocalisations']} re-localisation(s); "
        f"blocked {faults['blocked_moves']}/{faults['moves']} moves; robot node unknown "
        f"{faults['robot_node_unknown']}/{faults['robot_node_readings']}"
    )


AGENTS_GIVEN_THE_TASK = ("known-task", "oracle")

DEFAULT_TASKS = ((0, 1, 2), (1, 2, 3))  # the thesis's two ball placements (as the lab's DEFAULT_TASKS)
N_NODES = 5  # the lab graph's areas (the CLI does not change the graph)


def parse_tasks(text: str) -> list[list[int]]:
    """``"0,1,2;1,2,3"`` -> ``[[0, 1, 2], [1, 2, 3]]`` (ball nodes per task, tasks separated by ';')."""
    try:
        tasks = [[int(node) for node in part.split(",")] for part in text.split(";") if part.strip()]
    except ValueError as error:
        raise ConfigError(f"--tasks '{text}': expected ball nodes like '0,1,2;1,2,3' ({error})") from None
    if not tasks:
        raise ConfigError(f"--tasks '{text}': give at least one task, e.g. '0,1,2;1,2,3'")
    return tasks


class ToxicWasteSession:
    """Models built and solved once per process for one option set; envs and agents made from them."""

    def __init__(self, backend: str, options: dict):
        import gymnasium

        import embodied_adhoc.envs  # noqa: F401  (registers the env ids)
        from embodied_adhoc.decision.agents.factory import make_agent
        from embodied_adhoc.domains.lab import build_lab_library
        from embodied_adhoc.domains.lab_observations import LabObservation

        env_id = ENV_IDS[backend]
        if env_id not in gymnasium.registry:
            raise ConfigError(
                f"--backend {backend} needs the env '{env_id}', which is not registered in this installation"
            )
        self.backend = backend
        self.env_id = env_id
        self.env_kwargs = {
            "tasks": [list(t) for t in options["tasks"]],
            "human_epsilon": options["human_epsilon"],
            "communication": options["communication"],
            "confusion": options["confusion"],
        }
        if options.get("human"):  # a plug-in human in the world (envs.lab_humans); the models keep theirs
            self.env_kwargs["human"] = options["human"]
        model = {}
        if options.get("localisation_model") is not None:
            model["localisation_model"] = options["localisation_model"]
        if "model_rfid_miss" in options:
            if backend != "mujoco":
                raise ConfigError(
                    "--model-rfid-miss and --rfid-miss act on the physics lab's RFID reader: use --backend mujoco"
                )
            model["rfid_miss"] = options["model_rfid_miss"]
        self.env_kwargs.update(model)
        physical = fault_env_kwargs(options)
        if physical and backend != "mujoco":
            raise ConfigError(
                f"fault and localisation options ({', '.join(sorted(physical))}) act on the physics lab only: "
                "use --backend mujoco"
            )
        self.env_kwargs.update(physical)
        self.library = build_lab_library(
            tasks=options["tasks"],
            human_epsilon=options["human_epsilon"],
            communication=options["communication"],
            confusion=options["confusion"],
            **model,
        )
        self.task_names = tuple(
            "[" + ",".join(str(node) for node in task) + "]" for task in self.library.tasks
        )
        self._make_agent = make_agent
        self._observation = LabObservation
        # the physics env counts its fault events per episode (info["faults"]): one CSV column each
        self.trial_columns = (*fault_columns(), *CAP_COLUMNS) if backend == "mujoco" else ()

    def make_env(self, max_steps: int):
        import gymnasium

        # The runner's cap is the spec's TimeLimit (gymnasium.make's own keyword).
        return gymnasium.make(
            self.env_id, max_episode_steps=int(max_steps), disable_env_checker=True, **self.env_kwargs
        )

    def reset_options(self, spec: dict) -> dict:
        return {"task": spec["task"], "robot_node": spec["robot_node"], "human_node": spec["human_node"]}

    def make_agent(self, name: str, spec: dict, seed: int):
        if name in LEARNED_AGENTS:  # torch is imported only when a learned agent is asked for
            from embodied_adhoc.learning.index_domains import index_agent

            return index_agent(self.library, name, name=name)
        true_task = int(spec["task"]) if name in AGENTS_GIVEN_THE_TASK else None
        return self._make_agent(name, self.library, true_task=true_task, rng_seed=seed)

    def observation_index(self, observation) -> int:
        return self._observation.from_vector(observation, self.library.graph.n_nodes).encode()

    def trial_extras(self, trace, info: dict) -> dict:
        """The values of ``trial_columns`` for a finished episode: its fault counts (the last ``info["faults"]``) and,
        if it hit the step cap, why (:func:`cap_reason`)."""
        if not self.trial_columns:
            return {}
        from embodied_adhoc.envs.toxic_waste import FAULT_COUNTS

        faults = info["faults"]
        extras = {}
        for name, (kind, _) in FAULT_COUNTS.items():
            value = faults[name]
            extras[f"{kind}_{name}"] = round(float(value), 4) if isinstance(value, float) else int(value)
        capped = trace.truncated and not trace.success
        reason = cap_reason(trace.actions, faults, self.library.action_names, capped)
        extras.update(zip(CAP_COLUMNS, reason, strict=True))
        return extras


class ToxicWasteDomain:
    name = "toxic-waste"
    description = (
        "HOTSPOT lab: a robot helps a human put three toxic-waste balls in its container (thesis ch. 7)"
    )
    backends = ("abstract", "mujoco")
    agent_names = ("hotspot", "known-task", "oracle", "random", "atpo", "bopa", *LEARNED_AGENTS)
    default_agents = ("hotspot", "known-task", "oracle", "random")
    privileged_agents = ("oracle", "bopa")  # observes_state: marked in the tables
    blas_dependent = True  # ATPO's Perseus policies and BOPA's value iteration come from BLAS sums

    def input_files(self, options: dict) -> dict:
        """The files a run reads, by flag (their content is part of its identity: experiments/identity.py)."""
        from embodied_adhoc import paths
        from embodied_adhoc.domains.confusion import MEASURED_MATRIX, THESIS_MATRIX
        from embodied_adhoc.domains.lab_observations import MEASURED_LOCALISATION
        from embodied_adhoc.experiments.identity import plugin_source

        named = {"thesis": THESIS_MATRIX, "measured": MEASURED_MATRIX}
        confusion = options["confusion"]
        files = {"--confusion": paths.asset(named[confusion]) if confusion in named else confusion}
        model = options.get("localisation_model")
        if model is not None:
            files["--localisation-model"] = (
                paths.asset(MEASURED_LOCALISATION) if model == "measured" else model
            )
        files["--human"] = plugin_source("human", options.get("human"), "--human")
        return files

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        group = parser.add_argument_group("toxic-waste options")
        group.add_argument(
            "--human-epsilon",
            type=float,
            default=0.05,
            metavar="E",
            help="probability that the human fails to act in a step (default 0.05)",
        )
        group.add_argument(
            "--no-communication",
            action="store_true",
            help="ablation of Fig. 7.11: no 'locate human' action; the human is seen only when co-located",
        )
        group.add_argument(
            "--task",
            type=int,
            default=None,
            metavar="K",
            help="fix the true task to library index K (default: uniform per episode)",
        )
        group.add_argument(
            "--tasks",
            type=parse_tasks,
            default=None,
            metavar="NODES",
            help="task library as ball nodes per task, e.g. '0,1,2;1,2,3' (the default)",
        )
        group.add_argument(
            "--confusion",
            default=DEFAULT_CONFUSION,
            metavar="thesis|measured|PATH",
            help="speech confusion matrix of 'locate human' "
            "(default: measured, our offline pipeline's; 'thesis' = the original's)",
        )
        group.add_argument(
            "--human",
            default=None,
            metavar="scripted|MODULE:CALLABLE",
            help="the world's human teammate (default: the scripted cleaner the agents' models assume); a plug-in "
            "factory(library, task) -> object with step(rng, human_node, ball_status) (docs/plugins.md)",
        )
        faults = parser.add_argument_group("physics-lab faults and localisation (--backend mujoco)")
        add_fault_arguments(faults)

    def options_from_args(self, args: argparse.Namespace) -> dict:
        from embodied_adhoc.envs.lab_humans import human_option

        return human_option(args.human) | self.options(
            human_epsilon=args.human_epsilon,
            communication=not args.no_communication,
            task=args.task,
            tasks=args.tasks,
            confusion=args.confusion,
            faults=fault_options(args),
            localisation=not args.no_localisation,
            localisation_model=args.localisation_model,
            model_rfid_miss=args.model_rfid_miss,
        )

    def options(
        self,
        human_epsilon: float = 0.05,
        communication: bool = True,
        task: int | None = None,
        tasks=None,
        confusion: str = DEFAULT_CONFUSION,
        faults: dict | None = None,
        localisation: bool = True,
        localisation_model: str | None = None,
        model_rfid_miss: float | None = None,
    ) -> dict:
        """Validated, JSON-ready options (what identifies a run in its ``config.json``).

        ``model_rfid_miss`` is the agents' model of RFID misses; None: the ``rfid_miss`` fault's value, so that the
        model knows how often its reader fails (stored whenever either is given)."""
        tasks = [list(map(int, t)) for t in (tasks if tasks is not None else DEFAULT_TASKS)]
        if not 0.0 <= float(human_epsilon) <= 1.0:
            raise ConfigError(f"--human-epsilon must lie in [0, 1], got {human_epsilon}")
        if task is not None and not 0 <= int(task) < len(tasks):
            raise ConfigError(f"--task {task} is outside the task library 0..{len(tasks) - 1} ({tasks})")
        unknown = sorted(set(faults or {}) - set(FAULTS))
        if unknown:
            raise ConfigError(f"unknown fault(s) {unknown}; known: {', '.join(FAULTS)}")
        options = {
            "human_epsilon": float(human_epsilon),
            "communication": bool(communication),
            "task": None if task is None else int(task),
            "tasks": tasks,
            "confusion": str(confusion),
        }
        # only what differs from the defaults, so that stored runs made before these options still resume
        if faults:
            options["faults"] = {name: float(value) for name, value in faults.items()}
        if not localisation:
            options["localisation"] = False
        if localisation_model is not None:
            options["localisation_model"] = str(localisation_model)
        if model_rfid_miss is None and faults and "rfid_miss" in faults:
            model_rfid_miss = faults["rfid_miss"]
        if model_rfid_miss is not None:
            if not 0.0 <= float(model_rfid_miss) <= 1.0:
                raise ConfigError(f"--model-rfid-miss {model_rfid_miss}: must be in [0, 1]")
            options["model_rfid_miss"] = float(model_rfid_miss)
        return options

    def episode_spec(self, options: dict, rng: np.random.Generator) -> dict:
        drawn_task = int(rng.integers(len(options["tasks"])))
        robot_node, human_node = (int(n) for n in rng.integers(N_NODES, size=2))
        task = drawn_task if options.get("task") is None else int(options["task"])
        return {"task": task, "robot_node": robot_node, "human_node": human_node}

    def open_session(self, backend: str, options: dict) -> ToxicWasteSession:
        return ToxicWasteSession(backend, options)


DOMAIN = ToxicWasteDomain()
