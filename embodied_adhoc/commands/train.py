"""``embodied-adhoc train atlpo``: train an ATLPO-MF library (thesis chapter 6) and its classifier.

One PPO policy per environment of the chosen set (task x team), then the recurrent Bayesian classifier (Eq. 6.2)
on episodes each member plays in its own environment, evaluated per step (accuracy, posterior of the true
environment, expected calibration error) on held-out episodes. Everything goes to ``--out``: a safetensors file
per member and for the classifier, ``library.json`` and ``training.json`` (settings, cost, per-step scores).
Interrupted runs resume: members whose weights exist are loaded, not retrained.
"""

from __future__ import annotations

import argparse

from embodied_adhoc.commands.arguments import output_folder
from embodied_adhoc.errors import ConfigError

RECURRENT_DOMAINS = ("foraging", "pursuit", "toxic-waste", "pursuit-task", "ntu")
"""``learning.generalist.DOMAINS``, spelled out so that building the parser imports no torch (a test checks they
agree)."""


def handle_atlpo(args: argparse.Namespace) -> int:
    for name in ("steps", "envs", "episodes", "episode_steps", "iterations"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} {getattr(args, name)}: give a positive integer")
    if not 0.0 <= args.mixing <= 1.0:
        raise ConfigError(f"--mixing {args.mixing}: a probability in [0, 1]")
    from embodied_adhoc.learning.atlpo_train import AtlpoTraining, train_atlpo
    from embodied_adhoc.learning.ppo import pick_device

    pick_device(args.device)  # no CUDA for --device cuda: refused here, before the first policy starts
    values = {name: getattr(args, name) for name in AtlpoTraining.__dataclass_fields__}
    settings = AtlpoTraining(**{**values, "out": str(args.out)})
    report = train_atlpo(settings)
    print(
        f"library of {len(report['members'])} in {args.out} ({report['total_seconds']} s, "
        f"policies {report['policy_seconds']} s)"
    )
    print("step  accuracy  p(true)  ECE")
    scores = report["per_step"]
    for row in scores[:: max(1, len(scores) // 10)]:
        print(f"{row['step']:4d}  {row['accuracy']:8.2f}  {row['true_posterior']:7.2f}  {row['ece']:.3f}")
    return 0


def _length(row: dict) -> str:
    length = row["mean_episode_length"]
    return f"episode length {'-' if length is None else f'{length:.1f}'}"


def _train_recurrent(args, agent: str, settings, run, postfix, last) -> int:
    """The recurrent PPO agents' shared run: checks, device, progress bar, curve plot and the closing line;
    ``postfix(row)`` and ``last(final)`` give each agent's own progress and summary text."""
    for name in ("steps", "envs", "rollout", "threads"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name} {getattr(args, name)}: give a positive integer")
    if args.teammates < 0:
        raise ConfigError(f"--teammates {args.teammates}: give a positive count, or 0 for all")
    from tqdm import tqdm

    from embodied_adhoc.learning.ppo import pick_device

    pick_device(args.device)  # no CUDA for --device cuda: refused here, before training starts
    settings = settings()
    config = settings.config()  # settings that do not fit together are refused before training starts
    settings.env_kwargs()  # and so is a teammate count the train split does not have
    batch = config.num_envs * config.rollout_steps
    total = max(1, config.total_steps // batch) * batch  # whole updates
    with tqdm(total=total, unit="step", desc=f"{agent} {args.domain}", disable=args.quiet) as bar:

        def progress(steps: int, row: dict) -> None:
            bar.set_postfix_str(postfix(row))
            bar.update(steps - bar.n)

        report = run(settings, progress)
    _plot_curve(args.out / "curve.csv", args.out / "curve.png", args.domain, agent=agent)
    print(
        f"{agent} {args.domain}: {report['env_steps']} env steps in {report['train_seconds']} s "
        f"({report['steps_per_second']} steps/s) -> {args.out}; last update: mean episode length "
        f"{(report['final'] or {}).get('mean_episode_length')}, {last(report['final'] or {})}"
    )
    return 0


def _common(args) -> dict:
    """The settings every recurrent PPO agent's training takes from its flags."""
    return {
        "domain": args.domain,
        "out": str(args.out),
        "steps": args.steps,
        "seed": args.seed,
        "envs": args.envs,
        "rollout": args.rollout,
        "device": args.device,
        "threads": args.threads,
        "teammates": args.teammates,
        "pipeline": args.pipeline,
    }


def handle_generalist(args: argparse.Namespace) -> int:
    from embodied_adhoc.learning.generalist import GeneralistTraining, train_generalist_run

    def postfix(row: dict) -> str:
        solved = row["solved"]
        return f"{_length(row)} solved {'-' if solved is None else f'{solved:.2f}'}"

    return _train_recurrent(
        args,
        "ppo-generalist",
        lambda: GeneralistTraining(**_common(args)),
        train_generalist_run,
        postfix,
        lambda final: f"solved {final.get('solved')}",
    )


def handle_liam(args: argparse.Namespace) -> int:
    if not args.reconstruction >= 0.0:
        raise ConfigError(f"--reconstruction {args.reconstruction}: give a weight >= 0")
    from embodied_adhoc.learning.liam import LiamTraining, train_liam_run

    return _train_recurrent(
        args,
        "liam",
        lambda: LiamTraining(**_common(args), reconstruction_coef=args.reconstruction),
        train_liam_run,
        lambda row: f"{_length(row)} reconstruction {row['reconstruction_loss']:.3f}",
        lambda final: f"reconstruction loss {final.get('reconstruction_loss')}",
    )


def handle_meliba(args: argparse.Namespace) -> int:
    if args.latent < 1:
        raise ConfigError(f"--latent {args.latent}: give a positive integer")
    if not args.kl >= 0.0:
        raise ConfigError(f"--kl {args.kl}: give a weight >= 0")
    from embodied_adhoc.learning.meliba import MelibaTraining, train_meliba_run

    return _train_recurrent(
        args,
        "meliba",
        lambda: MelibaTraining(**_common(args), latent=args.latent, kl_coef=args.kl),
        train_meliba_run,
        lambda row: f"{_length(row)} elbo {row['elbo_loss']:.3f} variance {row['posterior_variance']:.3f}",
        lambda final: f"negative ELBO {final.get('elbo_loss')}",
    )


def _plot_curve(csv_path, png_path, domain: str, agent: str = "ppo-generalist") -> None:
    """Episode length and solved fraction against env steps, from the training curve's CSV."""
    import csv

    import matplotlib

    from embodied_adhoc.atomic import atomic_path

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    with open(csv_path, newline="") as handle:
        rows = [r for r in csv.DictReader(handle) if r["mean_episode_length"]]
    figure, (left, right) = plt.subplots(1, 2, figsize=(9, 3.2))
    steps = [int(r["env_steps"]) for r in rows]
    left.plot(steps, [float(r["mean_episode_length"]) for r in rows])
    left.set_ylabel("mean episode length (steps)")
    right.plot(steps, [float(r["solved"]) for r in rows])
    right.set_ylabel("episodes solved (fraction)")
    for axis in (left, right):
        axis.set_xlabel("env steps")
        axis.grid(alpha=0.3)
    figure.suptitle(f"{agent} {domain}: training episodes (teams drawn from the train population)")
    try:
        with atomic_path(png_path) as temporary:
            figure.savefig(temporary, format="png", dpi=110, bbox_inches="tight")
    finally:
        plt.close(figure)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "train",
        help="train learned agents (ATLPO-MF library and classifier, the recurrent PPO generalist)",
        description=__doc__.split("\n\n")[0],
    )
    kinds = parser.add_subparsers(dest="kind", metavar="KIND")
    parser.set_defaults(_parser=parser)
    atlpo = kinds.add_parser(
        "atlpo", help="one PPO policy per task x team environment, then the classifier", description=__doc__
    )
    atlpo.add_argument("--domain", choices=("foraging", "pursuit"), required=True)
    atlpo.add_argument(
        "--set",
        dest="set_name",
        choices=("task", "team", "task+team"),
        required=True,
        help="task: tasks 1-4 with tau1; team: tau0-2 on task 1; task+team: both (K=6)",
    )
    atlpo.add_argument(
        "--steps", type=int, default=30_000, help="env steps per policy (default 30000, the thesis's)"
    )
    atlpo.add_argument("--seed", type=int, default=0)
    atlpo.add_argument(
        "--envs", type=int, default=16, help="parallel sub-envs of the vector env (default 16)"
    )
    atlpo.add_argument(
        "--episodes", type=int, default=256, help="classifier training episodes per environment"
    )
    atlpo.add_argument("--episode-steps", type=int, default=30, help="steps kept per classifier episode")
    atlpo.add_argument("--iterations", type=int, default=600, help="classifier training iterations")
    atlpo.add_argument(
        "--mixing",
        type=float,
        default=0.5,
        help="chance per step that a classifier episode takes a random member's action (default 0.5)",
    )
    atlpo.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    atlpo.add_argument("--threads", type=int, default=0, help="torch CPU threads (default: torch's choice)")
    atlpo.add_argument(
        "--generalist",
        action="store_true",
        help="also train the model-free baseline on all the set's environments together",
    )
    atlpo.add_argument(
        "--model",
        choices=("mf", "mb"),
        default="mf",
        help="mf: ATLPO-MF (PPO end to end, Fig. 6.2); mb: ATLPO-MB (encoder, transition and reward "
        "predictors and decoder on replayed experience, then PPO on the latents, Fig. 6.3)",
    )
    atlpo.add_argument("--quiet", action="store_true", help="no progress bar")
    atlpo.add_argument(
        "--out",
        type=output_folder,
        required=True,
        help="folder for the weights, library.json and training.json (not an existing file)",
    )
    atlpo.set_defaults(func=handle_atlpo)
    generalist = _recurrent_parser(
        kinds,
        "ppo-generalist",
        300_000,
        help="one recurrent (GRU) PPO policy against teams drawn from the train population",
        description="The library-free ad hoc agent: a GRU actor-critic trained with PPO on the vector grid env, "
        "each episode's task and team drawn from the train population (tau0-tau2, tasks 1-4). Writes the "
        "weights (safetensors), curve.csv, curve.png and training.json to --out; an interrupted run resumes from "
        "the checkpoint there (same settings, same result).",
    )
    generalist.set_defaults(func=handle_generalist)
    liam = _recurrent_parser(
        kinds,
        "liam",
        120_000,
        help="the recurrent PPO policy with agent modelling (LIAM): its GRU state also decodes the teammates",
        description="LIAM (Papoudakis et al. 2021): train ppo-generalist's GRU actor-critic with, during training "
        "only, a decoder that reconstructs the teammates' observations and actions from the GRU state, its loss "
        "added to PPO's. Writes the weights without the decoder (safetensors), curve.csv, curve.png and "
        "training.json to --out; an interrupted run resumes from the checkpoint there.",
    )
    liam.add_argument(
        "--reconstruction", type=float, default=0.1, help="weight of the reconstruction loss (default 0.1)"
    )
    liam.set_defaults(func=handle_liam)
    meliba = _recurrent_parser(
        kinds,
        "meliba",
        120_000,
        help="a PPO policy conditioned on a variational belief over its teammates (MeLIBA / VariBAD)",
        description="MeLIBA (Zintgraf et al. 2021, after VariBAD): a recurrent encoder over the ego's own "
        "trajectory gives a Gaussian posterior over a latent teammate/task embedding, trained (ELBO) with a "
        "training-only decoder of future rewards and teammates' actions; a PPO policy reads the window and the "
        "posterior's mean and variance. Writes the weights without the decoder (safetensors), curve.csv, "
        "curve.png and training.json to --out; an interrupted run resumes from the checkpoint there.",
    )
    meliba.add_argument("--latent", type=int, default=8, help="size of the latent embedding (default 8)")
    meliba.add_argument("--kl", type=float, default=0.1, help="weight of the ELBO's KL term (default 0.1)")
    meliba.set_defaults(func=handle_meliba)


def _recurrent_parser(kinds, name: str, steps: int, **texts) -> argparse.ArgumentParser:
    """The flags every recurrent PPO agent's training takes (``_train_recurrent`` reads them)."""
    parser = kinds.add_parser(name, **texts)
    parser.add_argument(
        "--domain",
        choices=RECURRENT_DOMAINS,
        required=True,
        help="a grid arena (teams tau0-tau2) or a benchmark domain (teammates from its train split)",
    )
    parser.add_argument(
        "--teammates",
        type=int,
        default=0,
        help="train against the first N teams / train-split members only (default 0: all of them)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=steps,
        help=f"env steps in all, rounded down to whole updates (default {steps})",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--envs", type=int, default=32, help="parallel sub-envs (default 32)")
    parser.add_argument(
        "--rollout", type=int, default=64, help="steps per sub-env per update, the BPTT length (default 64)"
    )
    parser.add_argument("--device", choices=("auto", "cpu", "cuda"), default="cpu")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
    parser.add_argument(
        "--pipeline",
        action="store_true",
        help="grid domains: run the policy of half the sub-envs on a second thread while the env steps the "
        "other half (faster collection with many --envs on two or more cores; the same weights)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--out", type=output_folder, required=True, help="folder for the weights, curve and checkpoint"
    )
    return parser
