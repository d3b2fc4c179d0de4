"""Summaries of the chapter-4 sequential-teams protocol (records of ``experiments/domains/teamster_protocol.py``): per
agent and team the accumulated reward (prey captures on pursuit; the mean episode reward on the navigation
maps, Tables 4.5-4.7) at each evaluation point with percentile-bootstrap CIs over
trials, the after-learning matrix of Table 4.4, the changed-environment curve, captures per 500 steps, the
learning-curve figure (Fig. 4.7's layout) and the text table. No torch here: records are plain JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.plots import _pyplot, _save, line_with_band
from embodied_adhoc.experiments.stats import compare_pairs, summarise_sample
from embodied_adhoc.experiments.tables import format_table

PER = 500  # captures are reported per 500 steps (the PLASTIC reference's unit)


def trial_cell(values, scale: float) -> dict:
    """Mean, 95 % percentile-bootstrap CI and count of per-trial ``values`` times ``scale``, and the scaled values
    themselves (what Welch tests between agents and pooled summaries read)."""
    scaled = np.asarray(values, dtype=float) * scale
    s = summarise_sample(scaled)
    return {"mean": s.mean, "ci": [s.ci_low, s.ci_high], "n": s.n, "values": scaled.tolist()}


def load_records(folder: str | Path) -> list[dict]:
    """Every trial record under ``folder/runs`` (``AGENT/trial-K.json``)."""
    records = []
    for path in sorted(Path(folder, "runs").glob("*/trial-*.json")):
        try:
            records.append(json.loads(path.read_text()))
        except json.JSONDecodeError as error:
            raise ConfigError(
                f"{path}:{error.lineno}: not a trial record ({error.msg}); delete it to rerun that trial"
            ) from None
    return records


def summarise(records: list[dict]) -> dict:
    """The JSON summary: per agent, per team, curve points {step, captures (mean, CI), per 500} on pursuit or
    {step, reward (mean episode reward: mean, CI)} on a navigation map, the after-learning matrix and the
    changed-environment curve; ``metric`` names the key the tables and figure read."""
    out: dict = {}
    for agent in dict.fromkeys(r["agent"] for r in records):
        mine = [r for r in records if r["agent"] == agent]
        eval_steps = mine[0]["config"]["eval_steps"]
        navigation = mine[0]["config"].get("domain", "pursuit") != "pursuit"
        scale = PER / eval_steps

        def cells(values, scale=scale, navigation=navigation) -> dict:
            if navigation:
                return {"reward": trial_cell(values, 1.0)}
            return {"captures": trial_cell(values, 1.0), "per_500": trial_cell(values, scale)}

        entry: dict = {
            "trials": len(mine),
            "eval_steps": eval_steps,
            "curves": {},
            "after": {},
            "metric": "reward" if navigation else "per_500",
        }
        for team in mine[0]["curves"]:
            points = np.array([[c for _, c in r["curves"][team]] for r in mine])
            steps = [s for s, _ in mine[0]["curves"][team]]
            entry["curves"][team] = [{"step": s, **cells(points[:, i])} for i, s in enumerate(steps)]
        for learned in mine[0]["after"]:
            entry["after"][learned] = {
                team: cells([r["after"][learned][team] for r in mine]) for team in mine[0]["after"][learned]
            }
        if "changed" in mine[0]:
            points = np.array([[c for _, c in r["changed"]] for r in mine])
            entry["changed"] = [
                {"step": s, entry["metric"]: cells(points[:, i])[entry["metric"]]}
                for i, (s, _) in enumerate(mine[0]["changed"])
            ]
            # the robustness measure: each trial's mean over the evaluations after learning began (not step 0)
            entry["changed_after"] = (points[:, 1:].mean(axis=1) * (1.0 if navigation else scale)).tolist()
        if all(
            "changed_fit" in r for r in mine
        ):  # a learned model's fit to the changed rules (agent 0's move)
            fit = np.array(
                [r["changed_fit"] for r in mine], dtype=float
            )  # (trials, points, [step, share, P])
            entry["changed_fit"] = [
                {
                    "step": int(fit[0, i, 0]),
                    "share": trial_cell(fit[:, i, 1], 1.0),
                    "probability": trial_cell(fit[:, i, 2], 1.0),
                }
                for i in range(fit.shape[1])
            ]
        entry["seconds"] = float(np.mean([r.get("seconds", np.nan) for r in mine]))
        out[agent] = entry
    return out


def _metric(entry: dict) -> str:
    """The summary key of an agent's evaluations: ``per_500`` (pursuit captures) or ``reward`` (navigation)."""
    return entry.get("metric", "per_500")


def _fmt(cell: dict) -> str:
    low, high = cell["ci"]
    if np.isnan(low):
        return f"{cell['mean']:.1f}"
    return f"{cell['mean']:.1f} [{low:.1f}, {high:.1f}]"


def after_table(summary: dict, markdown: bool = False) -> str:
    """Table 4.4's layout: rows (agent, after learning tau_i), columns the evaluation teams; captures per 500
    steps, mean [95 % CI]."""
    teams = next(iter(summary.values()))["after"]
    rows = []
    for agent, entry in summary.items():
        for learned, evals in entry["after"].items():
            rows.append([agent, learned] + [_fmt(evals[team][_metric(entry)]) for team in teams])
    return format_table(["agent", "after learning"] + [f"eval {t}" for t in teams], rows, markdown)


def final_table(summary: dict, markdown: bool = False) -> str:
    """One row per agent: captures per 500 steps at the end of each team's interaction."""
    teams = next(iter(summary.values()))["curves"]
    rows = [
        [agent]
        + [_fmt(entry["curves"][t][-1][_metric(entry)]) for t in teams]
        + ([_fmt(entry["changed"][-1][_metric(entry)])] if "changed" in entry else [])
        + [f"{entry['seconds']:.0f}"]
        for agent, entry in summary.items()
    ]
    changed = ["changed env"] if any("changed" in e for e in summary.values()) else []
    return format_table(["agent"] + [f"end of {t}" for t in teams] + changed + ["s/trial"], rows, markdown)


def plot_curves(summary: dict, path: str | Path) -> Path:
    """Learning curves (captures per 500 steps vs interaction steps), one panel per team, CI bands."""
    plt = _pyplot()
    teams = list(next(iter(summary.values()))["curves"])
    figure, axes = plt.subplots(1, len(teams), figsize=(4.2 * len(teams), 3.4), sharey=True)
    for axis, team in zip(np.atleast_1d(axes), teams, strict=True):
        for agent, entry in summary.items():
            points = entry["curves"][team]
            x = [p["step"] for p in points]
            key = _metric(entry)
            mean = np.array([p[key]["mean"] for p in points])
            low = np.array([p[key]["ci"][0] for p in points])
            high = np.array([p[key]["ci"][1] for p in points])
            line_with_band(axis, x, mean, low, high, agent)
        axis.set_title(team)
        axis.set_xlabel("interaction steps")
    navigation = _metric(next(iter(summary.values()))) == "reward"
    np.atleast_1d(axes)[0].set_ylabel(
        "accumulated episode reward" if navigation else "prey captures per 500 steps"
    )
    np.atleast_1d(axes)[-1].legend(fontsize=7)
    return _save(figure, Path(path))


def changed_table(summary: dict, markdown: bool = False) -> str:
    """The changed-environment test of section 4.1.4 (TEAMSTER's robustness): per agent its trials' mean
    evaluation after learning began in the changed environment (captures per 500 steps on pursuit), mean [95 %
    CI], and between every two agents Welch's t and p on those per-trial values and the probability that the
    first scores more (:func:`~embodied_adhoc.experiments.stats.compare_pairs`). Empty without a changed phase."""
    changed = {agent: entry["changed_after"] for agent, entry in summary.items() if "changed_after" in entry}
    if not changed:
        return ""
    rows = [[agent, str(len(v)), _fmt(trial_cell(v, 1.0))] for agent, v in changed.items()]
    pairs = [
        [
            f"{c.first} vs {c.second}",
            f"{c.statistic:.2f}",
            f"{c.p_value:.3g}",
            "yes" if c.significant() else "no",
            f"{c.improvement:.2f}",
        ]
        for c in compare_pairs(changed, "changed", lower_is_better=False)
    ]
    return (
        format_table(["agent", "trials", "changed env, after learning began"], rows, markdown)
        + "\n\n"
        + format_table(["a vs b", "Welch t", "p", "p < 0.05", "P(a scores more)"], pairs, markdown)
    )


def plot_changed(summary: dict, path: str | Path) -> Path:
    """The changed phase: each agent's evaluations (CI bands) and, beside it, the learned environment models'
    share of the ad hoc agent's moves predicted in the changed rules (``changed_fit``)."""
    plt = _pyplot()
    figure, (left, right) = plt.subplots(1, 2, figsize=(8.4, 3.4))
    for agent, entry in summary.items():
        if "changed" not in entry:
            continue
        key = _metric(entry)
        points = entry["changed"]
        x = [p["step"] for p in points]
        low, high = np.array([p[key]["ci"] for p in points], dtype=float).T
        line_with_band(left, x, [p[key]["mean"] for p in points], low, high, agent)
        if "changed_fit" in entry:
            fit = entry["changed_fit"]
            right.plot([p["step"] for p in fit], [p["share"]["mean"] for p in fit], marker="o", label=agent)
    navigation = _metric(next(iter(summary.values()))) == "reward"
    left.set_ylabel("accumulated episode reward" if navigation else "prey captures per 500 steps")
    left.set_title("changed environment")
    right.set_ylabel("agent 0's move predicted (share)")
    right.set_ylim(0, 1)
    right.set_title("learned model vs the changed rules")
    for axis in (left, right):
        axis.set_xlabel("steps in the changed environment")
        axis.legend(fontsize=7)
    return _save(figure, Path(path))


def write_outputs(summary: dict, folder: str | Path) -> list[Path]:
    folder = Path(folder)
    changed = changed_table(summary, True)
    paths = [
        atomic_write_text(folder / "summary.json", json.dumps(summary, indent=2) + "\n"),
        atomic_write_text(
            folder / "table.md",
            "## After learning each team\n\n"
            + after_table(summary, True)
            + "\n\n## End of each interaction\n\n"
            + final_table(summary, True)
            + "\n"
            + (f"\n## Changed environment\n\n{changed}\n" if changed else ""),
        ),
        plot_curves(summary, folder / "curves.png"),
    ]
    if any("changed" in entry for entry in summary.values()):
        paths.append(plot_changed(summary, folder / "changed.png"))
    return paths
