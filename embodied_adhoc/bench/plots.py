"""The benchmark's plots: per scope (each domain and ``overall``), the agents' normalised IQM and mean with their
stratified-bootstrap intervals, and their performance profiles (score distributions with bands)."""

from __future__ import annotations

from pathlib import Path

from embodied_adhoc.experiments.plots import _pyplot, _save

__all__ = ["plot_summary"]


def _intervals(plt, scope: dict, title: str, path: Path) -> None:
    agents = list(scope["aggregate"])
    figure, axes = plt.subplots(1, 2, figsize=(9, 0.5 * len(agents) + 1.5), sharey=True)
    for axis, key in zip(axes, ("iqm", "mean"), strict=True):
        for row, agent in enumerate(agents):
            values = scope["aggregate"][agent]
            low, high = values[f"{key}_ci"]
            if low is not None and high is not None:
                axis.plot([low, high], [row, row], color="tab:blue", linewidth=6, alpha=0.5)
            axis.plot([values[key]], [row], "k|", markersize=14)
        axis.axvline(0.0, color="grey", linewidth=0.8)
        axis.axvline(1.0, color="grey", linewidth=0.8, linestyle="--")
        axis.set_xlabel(f"normalised {key.upper() if key == 'iqm' else key} (0 random, 1 best response)")
    axes[0].set_yticks(range(len(agents)), agents)
    figure.suptitle(title)
    _save(figure, path)


def _profiles(plt, scope: dict, title: str, path: Path) -> None:
    figure, axis = plt.subplots(figsize=(6, 4))
    for agent, curve in scope["profiles"].items():
        (line,) = axis.plot(curve["tau"], curve["fraction"], label=agent)
        if None not in curve["low"] and None not in curve["high"]:
            axis.fill_between(curve["tau"], curve["low"], curve["high"], color=line.get_color(), alpha=0.2)
    axis.set_xlabel("normalised score tau")
    axis.set_ylabel("fraction of episodes with score > tau")
    axis.set_title(title)
    axis.legend(fontsize="small")
    _save(figure, path)


def plot_summary(summary: dict, out: Path) -> list[Path]:
    """``<scope>-intervals.png`` and ``<scope>-profiles.png`` for every domain and ``overall`` with agents."""
    plt = _pyplot()
    scopes = {**summary["domains"], "overall": summary["overall"]}
    written = []
    for name, scope in scopes.items():
        if not scope.get("aggregate"):
            continue
        label = f"{name}: {summary['suite']} suite v{summary['version']} ({scope['members']} teammates)"
        for kind, draw in (("intervals", _intervals), ("profiles", _profiles)):
            path = Path(out) / f"{name}-{kind}.png"
            draw(plt, scope, label, path)
            written.append(path)
    return written
