"""Trained best responses to the grid arenas' benchmark members: the upper bound of a member's normalised score.

A member's best response is the ``ppo-generalist`` network trained with recurrent PPO
(:func:`~embodied_adhoc.learning.recurrent_ppo.train_recurrent_ppo`) on the vector env hosting that member alone:
``GridVectorEnv(domain, envs, teams=member.trial_options({})["teams"])``, the member's own trial option, so every
episode draws its task and start as the member's trials do and the member's team plays the teammate seats (a
policy team per sub-env, :mod:`~embodied_adhoc.learning.vector_grid`). Training starts from the shipped
``ppo-generalist`` weights (trained against tau0-tau2), because a policy trained from scratch on a budget of a few
minutes finishes far slower than the generalist does; the budget then goes to adapting it to the member.
The warm start enters the trainer as its model builder (``auxiliary.network``) with no extra loss.

The package ships one per held-out and validation member under ``bench/<domain>/best-response/<member>/``
(:func:`shipped_path`): the weights (safetensors, kind ``best-response``), ``training.json`` (the settings, env
steps, wall and CPU seconds) and ``curve.csv``, made by :data:`SHIPPED_COMMAND`. A trained best response is a lower
estimate of the true best response; :func:`~embodied_adhoc.bench.bounds.simulated_bounds` takes the better of it
and the original team. A plug-in spec ``embodied_adhoc.learning.best_response:<domain>/<member>`` names the shipped
best response of that member as an agent (``--agents``).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.generalist import (
    GeneralistTraining,
    generalist_agent,
    load_generalist,
    shipped_weights,
    train_generalist_run,
)
from embodied_adhoc.paths import assets_dir
from embodied_adhoc.teammates.best_responses import KIND, agent_spec, shipped_path, weights_digest

__all__ = [
    "KIND",
    "BestResponseAgentFactory",
    "BestResponseTraining",
    "agent_spec",
    "shipped_path",
    "train_best_response",
    "weights_digest",
]

STEPS = 102_400
SHIPPED_COMMAND = (
    ".venv/bin/python -m embodied_adhoc.learning.best_response --domain {domain} --member {member} --seed 0"
)
"""How the shipped best responses were made (``--member all``: every held-out and validation member in turn)."""


def _member(domain: str, member: str):
    from embodied_adhoc.teammates.populations import GRID, find_member

    if domain not in GRID:
        raise ConfigError(
            f"best response: domain {domain!r}; the trained best responses are of {', '.join(GRID)}"
        )
    spec = find_member(domain, member)
    if spec is None:
        raise ConfigError(
            f"best response: {domain} has no member {member!r} (`embodied-adhoc bench teammates --domain {domain}`)"
        )
    return spec


class _WarmStart:
    """The trainer's ``auxiliary``: the model starts as the shipped ``ppo-generalist``; no extra loss."""

    curve_fields: tuple[str, ...] = ()
    vector_kwargs: dict = {}

    def __init__(self, domain: str) -> None:
        self.path = shipped_weights(domain)
        relative = self.path.relative_to(assets_dir()).as_posix()
        self.metadata = {"warm_start": relative, "warm_start_sha256": weights_digest(self.path)}

    def network(self, network, recurrent: int):
        model, metadata = load_generalist(self.path)
        if model.config.as_dict() != network.as_dict() or model.recurrent != recurrent:
            raise ConfigError(
                f"best response: the warm start {self.path} is another network ({metadata['network']}, "
                f"GRU {model.recurrent}) than this grid's ({network.as_dict()}, GRU {recurrent})"
            )
        return model.train()

    def record(self, t: int, infos: dict) -> None:
        pass

    def loss(self, model, index):
        return torch.zeros((), device=next(model.parameters()).device), {}

    def exported(self, model):
        return model


@dataclass(frozen=True)
class BestResponseTraining(GeneralistTraining):
    """The ``train ppo-generalist`` settings against one member (``member``) instead of the train teams."""

    member: str = ""
    steps: int = STEPS

    def __post_init__(self) -> None:
        super().__post_init__()
        _member(self.domain, self.member)

    def env_kwargs(self) -> dict:
        return {"teams": list(_member(self.domain, self.member).trial_options({})["teams"])}


def __getattr__(name: str) -> BestResponseAgentFactory:
    """``embodied_adhoc.learning.best_response:<domain>/<member>``: the agent factory of that member's best
    response."""
    domain, _, member = name.partition("/")
    if not member:
        raise AttributeError(name)
    try:
        _member(domain, member)
    except ConfigError:
        raise AttributeError(name) from None
    return BestResponseAgentFactory(domain, member)


def train_best_response(domain: str, member: str, out: str | Path | None = None, **settings) -> dict:
    """Train ``member``'s best response into ``out`` (default: its shipped folder) with ``settings`` of
    ``BestResponseTraining`` (steps, seed, envs, rollout, threads); returns ``training.json``'s content, which adds
    the process's CPU seconds of the call (a folder already trained is returned as it is)."""
    if out is None:  # recorded relative to the working directory where it is inside (the repository's root)
        folder = shipped_path(domain, member).parent
        relative = os.path.relpath(folder)
        out = Path(relative if not relative.startswith("..") else folder)
    out = Path(out)
    training = BestResponseTraining(domain=domain, out=str(out), member=member, **settings)
    cpu = time.process_time()
    warm_start = _WarmStart(domain)
    report = train_generalist_run(training, auxiliary=warm_start, kind=KIND)
    if "cpu_seconds" not in report and report.get("finished"):
        report["cpu_seconds"] = round(time.process_time() - cpu, 1)
        report["warm_start"] = warm_start.metadata
        atomic_write_text(out / "training.json", json.dumps(report, indent=1) + "\n")
    return report


class BestResponseAgentFactory:
    """``factory(library, rng_seed)`` of a member's shipped best response (the agent plug-in interface)."""

    def __init__(self, domain: str, member: str) -> None:
        self.domain, self.member = domain, member
        self.path = shipped_path(domain, member)

    def __call__(self, library, rng_seed: int = 0):
        if not self.path.is_file():
            raise ConfigError(
                f"no trained best response of {self.domain}/{self.member} at {self.path}; train it with "
                f"`{SHIPPED_COMMAND.format(domain=self.domain, member=self.member)}`"
            )
        grid = library.rules.config
        return generalist_agent(self.domain, self.path, grid, name=KIND, kind=KIND)

    def __repr__(self) -> str:
        return f"BestResponseAgentFactory({self.domain!r}, {self.member!r})"


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="Train a grid member's best response (recurrent PPO).")
    parser.add_argument("--domain", default="foraging")
    parser.add_argument("--member", required=True, help="a member's name, or all (held-out and validation)")
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="default: the member's folder in the package's data")
    args = parser.parse_args(argv)
    if args.member == "all":
        from embodied_adhoc.teammates.populations import members

        if args.out is not None:
            raise ConfigError(
                "--member all trains into each member's folder in the package's data; drop --out"
            )
        names = [spec.name for split in ("heldout", "validation") for spec in members(args.domain, split)]
    else:
        names = [args.member]
    for name in names:
        report = train_best_response(args.domain, name, args.out, steps=args.steps, seed=args.seed)
        cost = {k: report[k] for k in ("env_steps", "train_seconds", "cpu_seconds") if k in report}
        print(name, json.dumps(cost), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
