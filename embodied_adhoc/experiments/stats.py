"""Trial statistics: t-distribution confidence intervals, Welch t-tests, and the thesis's trial metrics.

* Metric 1 (thesis Sec. 7.2, "number of steps to solve a task"): environment steps until the task is done.
* Metric 2 ("steps to identify the correct task"): the first step ``T`` from which the true task has the highest
  posterior probability and keeps it until the end of the trial. :func:`identify_step`.
* Metric 3 ("entropy in TEBOPA's belief over tasks"): the normalised entropy of the task posterior,
  :func:`normalised_entropies` (Sec. 7.1's ``H̄(b) = H(b) / log |M|``, the one that drives the action choice).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

CONFIDENCE = 0.95


@dataclass(frozen=True)
class SampleSummary:
    """Mean, sample standard deviation (ddof 1) and a two-sided t-distribution confidence interval."""

    n: int
    mean: float
    sd: float
    ci_low: float
    ci_high: float

    @property
    def ci_half_width(self) -> float:
        return (self.ci_high - self.ci_low) / 2.0


def summarise_sample(values: Sequence[float], confidence: float = CONFIDENCE) -> SampleSummary:
    """``mean ± t_{(1+c)/2, n-1} * sd / sqrt(n)``; NaN spread for fewer than two values, NaN mean for none."""
    from scipy import stats

    sample = np.asarray(values, dtype=np.float64)
    n = int(sample.size)
    if n == 0:
        return SampleSummary(0, math.nan, math.nan, math.nan, math.nan)
    mean = float(sample.mean())
    if n == 1:
        return SampleSummary(1, mean, math.nan, math.nan, math.nan)
    sd = float(sample.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1)) * sd / math.sqrt(n)
    return SampleSummary(n, mean, sd, mean - half, mean + half)


@dataclass(frozen=True)
class WelchTest:
    """Welch's unequal-variance t-test between two agents on one metric (two-sided)."""

    first: str
    second: str
    metric: str
    statistic: float
    p_value: float

    def significant(self, alpha: float = 0.05) -> bool:
        return bool(self.p_value < alpha)


def welch_test(first: Sequence[float], second: Sequence[float]) -> tuple[float, float]:
    """``(t, p)`` of ``scipy.stats.ttest_ind(first, second, equal_var=False)``; NaN when undefined.

    Undefined cases (fewer than two values on a side, or both samples constant) give NaN rather than a warning.
    """
    from scipy import stats

    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    if a.size < 2 or b.size < 2 or (np.ptp(a) == 0.0 and np.ptp(b) == 0.0):
        return math.nan, math.nan
    with warnings.catch_warnings():
        # One constant sample (e.g. an oracle that always takes 11 steps) is a valid Welch case; scipy's
        # "catastrophic cancellation" warning about it carries no information.
        warnings.filterwarnings("ignore", message="Precision loss occurred", category=RuntimeWarning)
        result = stats.ttest_ind(a, b, equal_var=False)
    return float(result.statistic), float(result.pvalue)


def pairwise_welch(samples: dict[str, Sequence[float]], metric: str) -> list[WelchTest]:
    """Welch tests between every pair of agents, in the order the agents are given."""
    names = list(samples)
    tests = []
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            statistic, p_value = welch_test(samples[first], samples[second])
            tests.append(WelchTest(first, second, metric, statistic, p_value))
    return tests


def normalised_entropies(distributions: np.ndarray) -> np.ndarray:
    """Metric 3 per row of a stack of task posteriors: the normalised entropy ``H̄`` of Sec. 7.1 (one place:
    :func:`embodied_adhoc.decision.agents.task_beliefs.normalised_entropy`), in [0, 1]."""
    from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

    return np.array([normalised_entropy(row) for row in np.atleast_2d(distributions)])


def identify_step(posteriors: np.ndarray, true_task: int) -> int | None:
    """Thesis Metric 2: the first step ``T`` from which ``true_task`` is the posterior's strict argmax to the end.

    ``posteriors[t]`` is the task posterior after ``t`` steps (row 0 = the prior before acting). A tie for the
    maximum does not count as identified (a uniform prior identifies nothing). Returns None if the true task is
    not the strict argmax at the last step (never identified), or if there are no posteriors.
    """
    posteriors = np.asarray(posteriors, dtype=np.float64)
    if posteriors.ndim != 2 or posteriors.shape[0] == 0:
        return None
    true_probability = posteriors[:, true_task]
    others = np.delete(posteriors, true_task, axis=1)
    best_other = others.max(axis=1) if others.shape[1] else np.full(len(posteriors), -np.inf)
    leading = true_probability > best_other
    if not leading[-1]:
        return None
    not_leading = np.flatnonzero(~leading)
    return int(not_leading[-1] + 1) if not_leading.size else 0


def mean_curve(curves: Sequence[Sequence[float]], confidence: float = CONFIDENCE) -> dict[str, np.ndarray]:
    """Per-time-step mean and t-interval over curves of different lengths (Fig. 7.9's entropy curve).

    A finished trial keeps its last value for later steps (its belief no longer changes), so every step averages
    over all trials. Returns arrays ``step``, ``mean``, ``low``, ``high``, ``n``.
    """
    from scipy import stats

    curves = [np.asarray(c, dtype=np.float64) for c in curves if len(c)]
    if not curves:
        empty = np.zeros(0)
        return {"step": empty, "mean": empty, "low": empty, "high": empty, "n": empty}
    length = max(c.size for c in curves)
    padded = np.stack([np.concatenate([c, np.full(length - c.size, c[-1])]) for c in curves])
    n = padded.shape[0]
    mean = padded.mean(axis=0)
    if n > 1:
        half = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1)) * padded.std(axis=0, ddof=1) / math.sqrt(n)
    else:
        half = np.full(length, np.nan)
    return {
        "step": np.arange(length),
        "mean": mean,
        "low": mean - half,
        "high": mean + half,
        "n": np.full(length, n),
    }
