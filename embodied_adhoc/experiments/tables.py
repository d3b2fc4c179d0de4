"""Plain-text and Markdown tables of a sweep summary (what ``trials`` and the reproduction scripts print)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from embodied_adhoc.experiments.stats import PairComparison, SampleSummary
from embodied_adhoc.experiments.summary import RunSummary


def format_table(headers: Sequence[str], rows: Sequence[Sequence[str]], markdown: bool = False) -> str:
    """Columns padded to their widest cell (numbers right-aligned); ``markdown`` gives a GitHub pipe table."""
    cells = [list(map(str, headers)), *[list(map(str, row)) for row in rows]]
    if markdown:
        lines = ["| " + " | ".join(cells[0]) + " |", "|" + "|".join("---" for _ in headers) + "|"]
        lines += ["| " + " | ".join(row) + " |" for row in cells[1:]]
        return "\n".join(lines)
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    numeric = [all(_looks_numeric(row[i]) for row in cells[1:]) for i in range(len(headers))]

    def line(row: list[str]) -> str:
        return "  ".join(
            c.rjust(w) if num else c.ljust(w) for c, w, num in zip(row, widths, numeric, strict=True)
        )

    return "\n".join([line(cells[0]), "  ".join("-" * w for w in widths), *map(line, cells[1:])]).rstrip()


def _looks_numeric(text: str) -> bool:
    return bool(text) and (text[0].isdigit() or text[0] in "-.[" or text == "n/a")


def fmt(value: float, digits: int = 2) -> str:
    return "n/a" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def mean_sd(sample: SampleSummary, digits: int = 2) -> str:
    if math.isnan(sample.mean):
        return "n/a"
    return fmt(sample.mean, digits) + ("" if math.isnan(sample.sd) else f" ± {fmt(sample.sd, digits)}")


def bounds(low: float, high: float, digits: int = 2) -> str:
    return "n/a" if low is None or math.isnan(low) else f"[{fmt(low, digits)}, {fmt(high, digits)}]"


def interval(sample: SampleSummary, digits: int = 2) -> str:
    """The sample's percentile-bootstrap interval of the mean."""
    return bounds(sample.ci_low, sample.ci_high, digits)


def p_value(value: float) -> str:
    if value is None or math.isnan(value):
        return "n/a"
    return f"{value:.3g}" if value >= 1e-3 else f"{value:.2e}"


CI_HEADER = "95% CI (bootstrap)"
"""Every interval in the tables is a percentile bootstrap (:mod:`embodied_adhoc.experiments.stats`)."""

SUMMARY_HEADERS = (
    "agent",
    "trials",
    "steps mean ± sd",
    f"steps {CI_HEADER}",
    "steps IQM",
    "success",
    "identify mean ± sd",
    "identified",
    "final H",
)


def summary_rows(summary: RunSummary) -> list[list[str]]:
    rows = []
    for s in summary.agents.values():
        rows.append(
            [
                s.agent,
                str(s.trials),
                mean_sd(s.steps),
                interval(s.steps),
                fmt(s.steps.iqm),
                fmt(s.success_rate),
                mean_sd(s.identify),
                fmt(s.identified_rate),
                fmt(s.final_entropy.mean),
            ]
        )
    return rows


def summary_table(summary: RunSummary, markdown: bool = False) -> str:
    """Per agent: Metric 1 (steps to finish: mean ± sd, 95 % percentile-bootstrap interval of the mean, IQM), success
    rate, Metric 2 (steps to identify, over the trials that identified; ``identified`` = their fraction), Metric 3
    (final normalised entropy)."""
    return format_table(SUMMARY_HEADERS, summary_rows(summary), markdown)


def comparison_table(
    summary: RunSummary | Sequence[PairComparison], markdown: bool = False, alpha: float = 0.05
) -> str:
    """Steps to finish compared between every pair of agents of a summary (or the comparisons given): Welch's
    t-test, and the probability that the first takes fewer steps than the second (rliable's probability of
    improvement) with its bootstrap interval."""
    comparisons = summary.comparisons if isinstance(summary, RunSummary) else summary
    rows = [
        [
            f"{c.first} vs {c.second}",
            fmt(c.statistic),
            p_value(c.p_value),
            "n/a" if math.isnan(c.p_value) else ("yes" if c.significant(alpha) else "no"),
            fmt(c.improvement),
            bounds(c.improvement_low, c.improvement_high),
        ]
        for c in comparisons
    ]
    headers = ("steps: a vs b", "Welch t", "p", f"p < {alpha}", "P(a fewer steps)", CI_HEADER)
    return format_table(headers, rows, markdown)
