"""PNG plots of sweeps (matplotlib, Agg backend, files written atomically): analogues of thesis Figs. 7.8, 7.9, 7.11.

* :func:`plot_steps` (Fig. 7.8): per agent, mean steps to finish and to identify the task, 95 % CI error bars.
* :func:`plot_entropy` (Fig. 7.9): mean normalised task-belief entropy per time step with a 95 % CI band.
* :func:`plot_settings` (Fig. 7.11): steps to finish per agent under several settings (e.g. with and without
  communication), grouped bars with 95 % CI error bars.

Every bar and band is the percentile-bootstrap interval of :mod:`embodied_adhoc.experiments.stats`, so it lies
inside the data's range by construction (no identify-step bar below 0, no entropy band outside [0, 1]); error bars
are asymmetric where the interval is.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import atomic_path
from embodied_adhoc.experiments.stats import SampleSummary, mean_curve
from embodied_adhoc.experiments.summary import RunSummary


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(figure, path: Path) -> Path:
    path = Path(path)
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, dpi=120, bbox_inches="tight")
    finally:
        _pyplot().close(figure)
    return path


def line_with_band(axes, x, mean, low, high, label: str, alpha: float = 0.2, **style) -> None:
    """A curve and its interval shaded in the curve's colour (``fill_between`` alone takes the next colour of the
    cycle, so bands and lines would not match); no band where the interval is undefined (NaN)."""
    (line,) = axes.plot(x, mean, label=label, **style)
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    if np.isfinite(low).all() and np.isfinite(high).all():
        axes.fill_between(x, low, high, alpha=alpha, color=line.get_color())


def _mean_and_error(sample: SampleSummary) -> tuple[float, tuple[float, float]]:
    """Bar height and its (below, above) error-bar lengths: the bootstrap interval around the mean."""
    mean = 0.0 if math.isnan(sample.mean) else sample.mean
    if math.isnan(sample.ci_low):
        return mean, (0.0, 0.0)
    return mean, (mean - sample.ci_low, sample.ci_high - mean)


def _error_bars(values: list[tuple[float, tuple[float, float]]]) -> np.ndarray:
    """matplotlib's asymmetric ``yerr``: shape (2, bars), row 0 below, row 1 above."""
    return np.array([error for _, error in values], dtype=np.float64).reshape(-1, 2).T


def _save_bars(figure, axes, names: list[str], ylabel: str, title: str, path: Path) -> Path:
    axes.set_xticks(np.arange(len(names)), names)
    axes.set_ylabel(ylabel)
    axes.set_title(title)
    axes.legend()
    axes.grid(axis="y", alpha=0.3)
    return _save(figure, path)


def plot_steps(
    summary: RunSummary, path: Path, title: str = "Steps to finish and to identify the task"
) -> Path:
    """Fig. 7.8 analogue: two bars per agent (finish, identify) with 95 % CI error bars."""
    plt = _pyplot()
    names = list(summary.agents)
    x = np.arange(len(names))
    width = 0.38
    figure, axes = plt.subplots(figsize=(1.6 * len(names) + 2.5, 4.0))
    for offset, label, key in (
        (-width / 2, "steps to finish", "steps"),
        (width / 2, "steps to identify", "identify"),
    ):
        present = [not math.isnan(getattr(summary.agents[n], key).mean) for n in names]
        values = [
            _mean_and_error(getattr(summary.agents[n], key)) for n, p in zip(names, present, strict=True) if p
        ]
        axes.bar(
            x[present] + offset,
            [v[0] for v in values],
            width,
            yerr=_error_bars(values),
            capsize=4,
            label=label,
        )
    return _save_bars(figure, axes, names, "steps (mean, 95% bootstrap CI)", title, path)


def plot_entropy(
    curves_by_agent: Mapping[str, Sequence[Sequence[float]]],
    path: Path,
    title: str = "Task-belief entropy per time step",
) -> Path:
    """Fig. 7.9 analogue: mean normalised entropy per step (finished trials hold their last value), 95 % bootstrap
    band (inside [0, 1]).

    Agents whose entropy is zero throughout (a posterior fixed on the true task) are left out.
    """
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(6.5, 4.0))
    for name, curves in curves_by_agent.items():
        if all(not np.any(np.asarray(c)) for c in curves):
            continue  # a posterior fixed on one task (known-task) has zero entropy throughout: nothing to show
        curve = mean_curve(curves)
        if not curve["step"].size:
            continue
        label = f"{name} (n={int(curve['n'][0])})"
        line_with_band(axes, curve["step"], curve["mean"], curve["low"], curve["high"], label, alpha=0.25)
    axes.set_xlabel("time step")
    axes.set_ylabel("normalised entropy of the task belief")
    axes.set_ylim(-0.02, 1.05)
    axes.set_title(title)
    if axes.get_legend_handles_labels()[1]:  # every agent left out: no legend to draw (and no warning)
        axes.legend()
    axes.grid(alpha=0.3)
    return _save(figure, path)


def plot_settings(
    summaries: Mapping[str, RunSummary], path: Path, title: str = "Steps to finish by setting"
) -> Path:
    """Fig. 7.11 analogue: for each agent, one bar per setting (e.g. "communication", "no communication")."""
    plt = _pyplot()
    settings = list(summaries)
    names = list(dict.fromkeys(name for s in summaries.values() for name in s.agents))
    x = np.arange(len(names))
    width = 0.8 / max(len(settings), 1)
    figure, axes = plt.subplots(figsize=(1.6 * len(names) + 2.5, 4.0))
    for index, setting in enumerate(settings):
        agents = summaries[setting].agents
        present = [n in agents for n in names]
        values = [_mean_and_error(agents[n].steps) for n in names if n in agents]
        offset = (index - (len(settings) - 1) / 2) * width
        axes.bar(
            x[present] + offset,
            [v[0] for v in values],
            width,
            yerr=_error_bars(values),
            capsize=4,
            label=setting,
        )
    return _save_bars(figure, axes, names, "steps to finish (mean, 95% bootstrap CI)", title, path)
