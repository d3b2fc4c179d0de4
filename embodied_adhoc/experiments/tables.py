"""Plain-text and Markdown tables of a sweep summary (what ``trials`` and the reproduction scripts print)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from embodied_adhoc.experiments.stats import SampleSummary, WelchTest
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


def interval(sample: SampleSummary, digits: int = 2) -> str:
    return (
        "n/a"
        if math.isnan(sample.ci_low)
        else f"[{fmt(sample.ci_low, digits)}, {fmt(sample.ci_high, digits)}]"
    )


def p_value(value: float) -> str:
    if value is None or math.isnan(value):
        return "n/a"
    return f"{value:.3g}" if value >= 1e-3 else f"{value:.2e}"


SUMMARY_HEADERS = (
    "agent",
    "trials",
    "steps mean ± sd",
    "steps 95% CI",
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
                fmt(s.success_rate),
                mean_sd(s.identify),
                fmt(s.identified_rate),
                fmt(s.final_entropy.mean),
            ]
        )
    return rows


def summary_table(summary: RunSummary, markdown: bool = False) -> str:
    """Per agent: Metric 1 (steps to finish, mean ± sd and 95 % t-CI), success rate, Metric 2 (steps to identify,
    over the trials that identified; ``identified`` = their fraction), Metric 3 (final normalised entropy)."""
    return format_table(SUMMARY_HEADERS, summary_rows(summary), markdown)


def welch_table(
    summary: RunSummary | Sequence[WelchTest], markdown: bool = False, alpha: float = 0.05
) -> str:
    """Welch's t-tests on steps to finish: between every pair of agents of a summary, or the tests given."""
    tests = summary.welch if isinstance(summary, RunSummary) else summary
    rows = [
        [
            f"{t.first} vs {t.second}",
            fmt(t.statistic),
            p_value(t.p_value),
            "n/a" if math.isnan(t.p_value) else ("yes" if t.significant(alpha) else "no"),
        ]
        for t in tests
    ]
    return format_table(("Welch t-test (steps)", "t", "p", f"p < {alpha}"), rows, markdown)
