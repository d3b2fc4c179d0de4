"""Chapter-6 table (ATLPO-MF side) for one trained library: average steps to finish of the original teammate,
the library member that knows the environment (model-free RL), ATLPO-MF and random, beside the thesis's numbers,
and the posterior of the true environment per step.

    .venv/bin/python -m embodied_adhoc.cli train atlpo --domain foraging --set team --out runs/atlpo/foraging-team
    .venv/bin/python scripts/reproduce_atlpo.py --library runs/atlpo/foraging-team [--episodes 16 --seed 0]

Not yet here (issue 15): ATLPO-MB and the model-based column, the 3 training seeds, the held-out teammates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args

# results-to-reproduce.md, chapter 6: (set, domain) -> original, model-free RL, ATLPO-MF, random (the thesis's
# model-free RL column is printed beside both our members that know the environment and our mf-all policy)
THESIS = {
    ("task", "foraging"): (6.72, 7.56, 13.02, 59.05), ("task", "pursuit"): (9.36, 11.22, 21.36, 50.66),
    ("team", "foraging"): (9.2, 7.68, 8.85, 53.71), ("team", "pursuit"): (14.45, 10.19, 10.71, 58.21),
    ("task+team", "foraging"): (7.89, 7.62, 11.96, 56.52), ("task+team", "pursuit"): (11.54, 10.71, 16.75, 54.21),
}


@dataclass(frozen=True)
class Args:
    library: Path = Path("runs/atlpo/foraging-team")
    """a folder written by `embodied-adhoc train atlpo`"""
    episodes: int = 16
    """episodes per library environment (the thesis: 16)"""
    seed: int = 0
    max_steps: int = 200
    """step cap; an unfinished episode counts it"""
    threads: int = 1


def main(args: Args) -> None:
    import json

    import torch

    from embodied_adhoc.learning.atlpo import generalist_path, load_library, load_policy
    from embodied_adhoc.learning.atlpo_eval import AGENTS, evaluate

    torch.set_num_threads(args.threads)
    library, classifier = load_library(args.library)
    if classifier is None:
        raise SystemExit(f"{args.library}: the library has no classifier yet; rerun `embodied-adhoc train atlpo`")
    training = json.loads((args.library / "training.json").read_text())
    path = generalist_path(args.library, library.domain, training["set"])
    generalist = load_policy(path) if path.exists() else None
    results = evaluate(library, classifier, args.episodes, args.seed, args.max_steps, generalist=generalist)
    thesis = dict(zip(("original", "known", "atlpo-mf", "random"),
                      THESIS.get((training["set"], library.domain), (float("nan"),) * 4), strict=True))
    thesis["mf-all"] = thesis["known"]
    print(f"{library.domain}, set {training['set']} (K={len(library.policies)}), {args.episodes} episodes per "
          f"environment, seed {args.seed}, cap {args.max_steps} steps; policies trained {training['steps']} steps")
    print(f"{'agent':10s} {'steps':>7s} {'+-sd':>6s} {'solved':>7s} {'thesis':>7s}")
    for name in (a for a in AGENTS if a in results):
        steps = np.array(results[name]["steps"], float)
        print(f"{name:10s} {steps.mean():7.2f} {steps.std():6.2f} {np.mean(results[name]['finished']):7.2f} "
              f"{thesis[name]:7.2f}")
    belief = results["true_posterior_per_step"]
    marks = [t for t in (0, 1, 2, 4, 9, 19) if t < len(belief)]
    print("ATLPO-MF posterior of the true environment after step: "
          + ", ".join(f"{t + 1}: {belief[t]:.2f}" for t in marks))


if __name__ == "__main__":
    main(parse_dataclass_args(Args, description=__doc__))
