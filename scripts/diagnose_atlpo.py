"""Two diagnostics of ATLPO (thesis chapter 6) behind the figures in docs/atlpo.md.

``--what teams``: can the three teams (tau0-tau2, task 1) be told apart at all, and by whom? On the same held-out
episodes it scores, after each step, (a) the Bayes-optimal posterior from the *full state* with each team's exact
scripted policy as its likelihood (``P(teammates' next cells | state, own action, team)`` by Monte Carlo over the
policy's tie-break uniforms): an upper bound for any classifier; (b) the project's recurrent classifier (Eq. 6.2,
``learning/classifier.py``) on the 5x5 egocentric window ATLPO sees; (c) the same classifier on a 9x9 window,
which covers the whole 5x5 grid from any cell (full observability, same network). Its training accuracy is
printed beside the held-out one. The ad hoc agent takes the team policy's own action with probability
``--mixing``, else a uniform one (as the library classifier's data mixes members and random members).

``--what mb``: one ATLPO-MB member (LBF or pursuit, task 1 with tau1) trained with given world-model settings
against ATLPO-MF, each scored on 64 episodes with sampled actions (mean steps, cap 200).

    .venv/bin/python scripts/diagnose_atlpo.py --what teams --domain foraging [--train-episodes 256]
    .venv/bin/python scripts/diagnose_atlpo.py --what mb --head-hidden 0 --policy-learning-rate 0.00025

Seeded (``--seed``); one CPU thread. Prints one JSON line.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args


@dataclass(frozen=True)
class Args:
    what: str = "teams"
    """teams (identifiability of the team set) or mb (one ATLPO-MB member against ATLPO-MF)"""
    domain: str = "foraging"
    seed: int = 0
    train_episodes: int = 256
    """teams: classifier training episodes per team (the library's default)"""
    test_episodes: int = 32
    """teams: held-out episodes per team"""
    iterations: int = 600
    """teams: classifier iterations (the library's default)"""
    mixing: float = 0.5
    """teams: chance per step that the ad hoc agent takes the team policy's own action (else uniform)"""
    draws: int = 256
    """teams: Monte-Carlo draws per team and step of the oracle's likelihood"""
    views: tuple[int, ...] = (5, 9)
    """teams: egocentric windows to train the classifier on"""
    steps: int = 30_000
    """mb: PPO env steps"""
    policy_learning_rate: float = 1e-3
    head_hidden: int = 64
    updates_per_rollout: int = 0


HORIZON, SHOWN = 30, 12  # classifier episode length (the library's) and the steps printed


def team_episodes(args: Args, rng: np.random.Generator, count: int, oracle: bool):
    """``count`` episodes per team: {view: Trajectories}, and per episode the oracle's argmax-correct flags
    after each transition (None past the episode's end)."""
    from embodied_adhoc.domains.grid_rules import GridBatch, GridConfig, GridRules, rotation_tasks
    from embodied_adhoc.domains.grid_rules_obs import egocentric_observation
    from embodied_adhoc.domains.grid_rules_team import TEAM_DRAWS, TeamTable, planner_for
    from embodied_adhoc.learning.classifier import Trajectories
    from embodied_adhoc.teammates.foraging_teams import FORAGING_TEAMS
    from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS

    rules = GridRules(GridConfig(domain=args.domain))
    planner, n = planner_for(rules), rules.config.n_agents
    teams = FORAGING_TEAMS if args.domain == "foraging" else PURSUIT_TEAMS
    names = ("tau0", "tau1", "tau2")
    offsets = np.array(rotation_tasks(n)[0].offsets)[None]

    def step(state, own: int, team: str, k: int):
        batch = GridBatch.stack([state] * k)
        task = np.broadcast_to(offsets, (k, n, 2))
        actions = planner.actions(
            batch, task, False, TeamTable.of([teams[team]] * k), rng.random((k, n, TEAM_DRAWS))
        )
        actions[:, 0] = own
        prey = rng.random((k, rules.config.n_targets, 2)) if rules.prey_draws() else None
        return rules.plan_batch(batch, task, False, actions, prey)

    observations = {view: [] for view in args.views}
    previous, labels, lengths, verdicts = [], [], [], []
    for label, team in enumerate(names):
        for _ in range(count):
            state, log_posterior = rules.sample_state(rng), np.zeros(len(names))
            seen = {view: [] for view in args.views}
            actions, correct = [5], []  # 5: the classifier's "no previous action" slot
            for _ in range(HORIZON):
                for view in args.views:
                    seen[view].append(egocentric_observation(rules, state, 0, view))
                own = planner.actions(
                    GridBatch.stack([state]),
                    offsets,
                    False,
                    TeamTable.of([teams[team]]),
                    rng.random((1, n, TEAM_DRAWS)),
                )[0, 0]
                action = int(own) if rng.random() < args.mixing else int(rng.integers(5))
                real = step(state, action, team, 1)
                if oracle:
                    for j, other in enumerate(names):
                        simulated = step(state, action, other, args.draws)
                        match = np.all(simulated.agents[:, 1:] == real.agents[0, 1:], axis=(1, 2))
                        if rules.prey_draws():
                            match &= np.all(simulated.targets == real.targets[0], axis=(1, 2))
                        log_posterior[j] += np.log(max(match.mean(), 1e-3))
                    correct.append(
                        log_posterior.argmax() == label
                        if np.ptp(log_posterior) > 0
                        else rng.random() < 1 / len(names)
                    )
                state = rules.apply(state, type(real)(real.agents[0], real.targets[0], real.completed[0]))
                if not state.alive.any():
                    break
                actions.append(action)
            length = len(seen[args.views[0]])
            for view in args.views:
                padding = np.zeros((HORIZON - length, *seen[view][0].shape), np.float32)
                observations[view].append(np.concatenate([np.stack(seen[view]), padding]))
            previous.append(np.array(actions[:length] + [5] * (HORIZON - length)))
            labels.append(label)
            lengths.append(length)
            verdicts.append(correct + [None] * (HORIZON - len(correct)))
    data = {
        view: Trajectories(
            np.stack(observations[view]).astype(np.float32),
            np.stack(previous),
            np.array(labels),
            np.array(lengths),
        )
        for view in args.views
    }
    return data, verdicts


def teams(args: Args) -> dict:
    import torch

    from embodied_adhoc.learning.classifier import (
        ClassifierConfig,
        ClassifierTraining,
        RecurrentBayesianClassifier,
        per_step_scores,
        train_classifier,
    )

    rng = np.random.default_rng(args.seed)
    train, _ = team_episodes(args, rng, args.train_episodes, oracle=False)
    test, verdicts = team_episodes(args, rng, args.test_episodes, oracle=True)
    out = {
        "what": "teams",
        "domain": args.domain,
        "train_episodes_per_team": args.train_episodes,
        "test_episodes_per_team": args.test_episodes,
        "iterations": args.iterations,
    }
    for view in args.views:
        torch.manual_seed(args.seed)
        model = RecurrentBayesianClassifier(
            ClassifierConfig(channels=train[view].observations.shape[2], environments=3, view=view)
        )
        train_classifier(model, train[view], ClassifierTraining(iterations=args.iterations, seed=args.seed))
        for split, data in (("held_out", test[view]), ("training", train[view])):
            scores = per_step_scores(model, data)[:SHOWN]
            out[f"classifier_view{view}_{split}"] = [round(r["accuracy"], 3) for r in scores]
            # the episodes behind each accuracy: what a comparison of two runs' accuracies weighs them by
            out[f"classifier_view{view}_{split}_episodes"] = [r["episodes"] for r in scores]
    # the classifier's step t has seen t transitions; the oracle's verdict t-1 comes after t transitions
    live = [[v[t - 1] for v in verdicts if v[t - 1] is not None] for t in range(1, SHOWN)]
    out["oracle_full_state_held_out"] = [round(1 / 3, 3)] + [round(float(np.mean(v)), 3) for v in live]
    out["episodes_reaching_step"] = [len(verdicts)] + [len(v) for v in live]
    return out


def mean_steps(
    model, domain: str, env_kwargs: dict, episodes: int = 64, seed: int = 123, cap: int = 200
) -> float:
    """Mean steps to finish (cap for unfinished) over ``episodes`` with actions sampled from ``model``."""
    import torch

    from embodied_adhoc.learning.vector_grid import GridVectorEnv

    env = GridVectorEnv(domain, 16, max_episode_steps=cap, **env_kwargs)
    observation, _ = env.reset(seed=seed)
    generator = torch.Generator().manual_seed(seed)
    lengths, current, resetting = [], np.zeros(16, np.int64), np.zeros(16, bool)
    while len(lengths) < episodes:
        with torch.no_grad():
            logits, _ = model(torch.as_tensor(observation))
            action = torch.multinomial(torch.softmax(logits, -1), 1, generator=generator)[:, 0].numpy()
        observation, _, terminated, truncated, _ = env.step(action)
        current += ~resetting
        for index in np.flatnonzero(terminated | truncated):
            lengths.append(int(current[index]) if terminated[index] else cap)
            current[index] = 0
        resetting = terminated | truncated
    return float(np.mean(lengths[:episodes]))


def mb(args: Args) -> dict:
    from embodied_adhoc.learning.ppo import PpoConfig, train_ppo
    from embodied_adhoc.learning.world_model import WorldModelTraining, train_mb_policy

    kwargs = {"tasks": (1,), "teams": ("tau1",)}
    config = PpoConfig(total_steps=args.steps, seed=args.seed, device="cpu")
    settings = WorldModelTraining(
        seed=args.seed,
        policy_learning_rate=args.policy_learning_rate,
        head_hidden=args.head_hidden,
        updates_per_rollout=args.updates_per_rollout,
    )
    out = {
        "what": "mb",
        "domain": args.domain,
        "seed": args.seed,
        "steps": args.steps,
        "world_model": {
            k: getattr(settings, k) for k in ("policy_learning_rate", "head_hidden", "updates_per_rollout")
        },
    }
    start = time.process_time()
    result = train_mb_policy(args.domain, kwargs, config, settings)[0]
    out["atlpo_mb_steps"], out["mb_cpu_seconds"] = (
        mean_steps(result.model, args.domain, kwargs),
        round(time.process_time() - start, 1),
    )
    start = time.process_time()
    out["atlpo_mf_steps"] = mean_steps(train_ppo(args.domain, kwargs, config).model, args.domain, kwargs)
    out["mf_cpu_seconds"] = round(time.process_time() - start, 1)
    return out


def main(args: Args) -> None:
    import torch

    torch.set_num_threads(1)
    if args.what not in ("teams", "mb"):
        raise SystemExit(f"--what {args.what}: use teams or mb")
    print(json.dumps(teams(args) if args.what == "teams" else mb(args)), flush=True)


if __name__ == "__main__":
    main(parse_dataclass_args(Args, description=__doc__))
