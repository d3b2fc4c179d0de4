"""Trial statistics: bootstrap confidence intervals, IQM, probability of improvement, Welch t-tests, and the thesis's
trial metrics.

* Metric 1 (thesis Sec. 7.2, "number of steps to solve a task"): environment steps until the task is done.
* Metric 2 ("steps to identify the correct task"): the first step ``T`` from which the true task's posterior exceeds
  every other task's by more than :data:`IDENTIFY_MARGIN` until the end of the trial. :func:`identify_step`.
* Metric 3 ("entropy in TEBOPA's belief over tasks"): the normalised entropy of the task posterior,
  :func:`normalised_entropies` (Sec. 7.1's ``H̄(b) = H(b) / log |M|``, the one that drives the action choice).

Intervals (:data:`CI_METHOD`): a **percentile bootstrap** of the statistic (``BOOTSTRAP_REPS`` resamples of the
trials, seeded by ``BOOTSTRAP_SEED``), as rliable's ``get_interval_estimates`` does by default. A resampled mean
or IQM is itself a mean of observed values, so the interval never leaves ``[min, max]`` of the data: a step count
cannot get a negative bound, an entropy band stays in [0, 1] (the t-interval ``mean ± t sd / sqrt(n)`` did not on
skewed or capped data). The Welch t-test (:func:`welch_test_from_stats`, from summary statistics, and
:func:`welch_test` on samples) is kept for the thesis's claims, which used it. IQM and probability of
improvement follow rliable (Agarwal et al. 2021, "Deep RL at the
Edge of the Statistical Precipice"), written here in numpy.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

CONFIDENCE = 0.95
BOOTSTRAP_REPS = 10_000
BOOTSTRAP_SEED = 0
CI_METHOD = "percentile bootstrap"
IDENTIFY_MARGIN = 1e-6
"""Metric 2 needs the true task ahead of every other by more than this: a posterior of ``[0.5000000000000001,
0.5]`` (a rounding artefact of the belief update) identifies nothing."""

# Bootstrap resamples are drawn in blocks of about this many values, so memory stays bounded for long sweeps.
_CHUNK_ELEMENTS = 2_000_000


# ----------------------------------------------------------------------------------------------- point estimates


def interquartile_mean(values: np.ndarray, axis: int = -1) -> np.ndarray | float:
    """IQM: the mean of the middle 50 % of the values (25 % trimmed from each end, ``int(0.25 n)`` values each side,
    as ``scipy.stats.trim_mean(x, 0.25)`` and rliable's ``aggregate_iqm``)."""
    ordered = np.sort(np.asarray(values, dtype=np.float64), axis=axis)
    n = ordered.shape[axis]
    cut = int(0.25 * n)
    kept = np.take(ordered, np.arange(cut, n - cut), axis=axis)
    result = kept.mean(axis=axis)
    return float(result) if np.ndim(result) == 0 else result


def _better_matrix(first: np.ndarray, second: np.ndarray, lower_is_better: bool) -> np.ndarray:
    """``M[i, j] = 1`` if ``first[i]`` beats ``second[j]``, ``0.5`` on a tie, else 0."""
    difference = first[:, None] - second[None, :]
    if lower_is_better:
        difference = -difference
    return (difference > 0) + 0.5 * (difference == 0)


def probability_of_improvement(
    first: Sequence[float], second: Sequence[float], lower_is_better: bool = False
) -> float:
    """rliable's probability of improvement of ``first`` over ``second``: ``P(X > Y) + P(X = Y) / 2`` for X, Y drawn
    from the two samples (the Mann-Whitney U statistic over ``n m``); ``lower_is_better`` reads ``<`` (steps)."""
    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    if a.size == 0 or b.size == 0:
        return math.nan
    return float(_better_matrix(a, b, lower_is_better).mean())


# ----------------------------------------------------------------------------------------------- bootstrap


def _percentile_interval(replicates: np.ndarray, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(replicates, [tail, 1.0 - tail], axis=0)
    return low, high


def _resample_counts(labels: np.ndarray, n_labels: int, reps: int, rng: np.random.Generator) -> np.ndarray:
    """Resample the items (``labels[i]`` is item i's label in ``0..n_labels-1``) ``reps`` times with replacement and
    count how often each label was drawn in each resample: float array of shape (reps, n_labels)."""
    n = labels.size
    drawn = labels[rng.integers(0, n, size=(reps, n))]
    offsets = (drawn + n_labels * np.arange(reps)[:, None]).ravel()
    return np.bincount(offsets, minlength=reps * n_labels).reshape(reps, n_labels).astype(np.float64)


def _chunks(reps: int, width: int) -> list[int]:
    size = max(1, _CHUNK_ELEMENTS // max(width, 1))
    return [min(size, reps - start) for start in range(0, reps, size)]


def bootstrap_interval(
    values: Sequence[float],
    statistic: Callable[[np.ndarray], np.ndarray],
    confidence: float = CONFIDENCE,
    reps: int = BOOTSTRAP_REPS,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic`` (which maps a ``(reps, n)`` block of resamples to ``reps``
    values). NaN for fewer than two values."""
    sample = np.asarray(values, dtype=np.float64)
    n = sample.size
    if n < 2:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    replicates = np.concatenate(
        [statistic(sample[rng.integers(0, n, size=(block, n))]) for block in _chunks(reps, n)]
    )
    # A resampled mean lies in [min, max]; the clip only removes floating-point rounding of the summation.
    low, high = _percentile_interval(np.clip(replicates, sample.min(), sample.max()), confidence)
    return float(low), float(high)


@dataclass(frozen=True)
class SampleSummary:
    """Mean, sample standard deviation (ddof 1), IQM, and percentile-bootstrap intervals of the mean and the IQM."""

    n: int
    mean: float
    sd: float
    ci_low: float
    ci_high: float
    iqm: float = math.nan
    iqm_ci_low: float = math.nan
    iqm_ci_high: float = math.nan


def summarise_sample(
    values: Sequence[float],
    confidence: float = CONFIDENCE,
    reps: int = BOOTSTRAP_REPS,
    seed: int = BOOTSTRAP_SEED,
) -> SampleSummary:
    """Summary of one agent's metric over its trials; intervals are percentile bootstraps (seeded: same values, same
    interval), inside ``[min, max]`` by construction. NaN spread and intervals for fewer than two values."""
    sample = np.asarray(values, dtype=np.float64)
    n = int(sample.size)
    if n == 0:
        return SampleSummary(0, math.nan, math.nan, math.nan, math.nan)
    mean = float(sample.mean())
    iqm = interquartile_mean(sample)
    if n == 1:
        return SampleSummary(1, mean, math.nan, math.nan, math.nan, iqm)
    low, high = bootstrap_interval(sample, lambda block: block.mean(axis=1), confidence, reps, seed)
    iqm_low, iqm_high = bootstrap_interval(sample, interquartile_mean, confidence, reps, seed)
    return SampleSummary(n, mean, float(sample.std(ddof=1)), low, high, iqm, iqm_low, iqm_high)


def improvement_interval(
    first: Sequence[float],
    second: Sequence[float],
    lower_is_better: bool = False,
    confidence: float = CONFIDENCE,
    reps: int = BOOTSTRAP_REPS,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile bootstrap of :func:`probability_of_improvement`, both samples resampled independently (rliable's
    stratified bootstrap with one task).

    A resample is summarised by how often it holds each distinct value ``u_k`` (counts ``c_a``, ``c_b``); then
    ``P = sum_k c_a[k] (c_b[beaten by u_k] + c_b[k] / 2) / (n m)``, a cumulative sum over the distinct values, so a
    resample costs ``O(n + m + K)``, not ``O(n m)``.
    """
    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    if a.size < 2 or b.size < 2:
        return math.nan, math.nan
    values = np.unique(np.concatenate([a, b]))  # ascending
    a_index, b_index = np.searchsorted(values, a), np.searchsorted(values, b)
    if lower_is_better:  # order the values from worst to best, so "beaten by u_k" is "earlier in the order"
        a_index, b_index = values.size - 1 - a_index, values.size - 1 - b_index
    rng = np.random.default_rng(seed)
    replicates = []
    for block in _chunks(reps, a.size + b.size):
        counts_a = _resample_counts(a_index, values.size, block, rng)
        counts_b = _resample_counts(b_index, values.size, block, rng)
        beaten = np.cumsum(counts_b, axis=1) - counts_b  # second's resampled values strictly worse than u_k
        replicates.append((counts_a * (beaten + 0.5 * counts_b)).sum(axis=1) / (a.size * b.size))
    low, high = _percentile_interval(np.concatenate(replicates), confidence)
    return float(low), float(high)


# ----------------------------------------------------------------------------------------------- comparisons


def welch_test(first: Sequence[float], second: Sequence[float]) -> tuple[float, float]:
    """``(t, p)`` of Welch's test on two samples (``scipy.stats.ttest_ind(first, second, equal_var=False)``): their
    means, sample standard deviations and sizes through :func:`welch_test_from_stats`; NaN when undefined."""
    a = np.asarray(first, dtype=np.float64)
    b = np.asarray(second, dtype=np.float64)
    return welch_test_from_stats(
        float(a.mean()) if a.size else math.nan, _sample_sd(a), a.size,
        float(b.mean()) if b.size else math.nan, _sample_sd(b), b.size,
    )  # fmt: skip


def holm_adjusted(pvalues: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjustment of ``m`` p-values for the family-wise error rate: the k-th smallest times
    ``m - k + 1``, made non-decreasing in that order and capped at 1, returned in the input's order. A test is
    rejected at family-wise level alpha where its adjusted p-value is below alpha."""
    p = np.asarray(pvalues, dtype=np.float64)
    order = np.argsort(p, kind="stable")
    scaled = np.minimum(1.0, p[order] * (p.size - np.arange(p.size)))
    adjusted = np.empty_like(p)
    adjusted[order] = np.maximum.accumulate(scaled) if p.size else scaled
    return adjusted


def _sample_sd(sample: np.ndarray) -> float:
    return float(sample.std(ddof=1)) if sample.size > 1 else math.nan


def welch_test_from_stats(
    first_mean: float, first_sd: float, first_n: int, second_mean: float, second_sd: float, second_n: int
) -> tuple[float, float]:
    """``(t, p)`` of Welch's unequal-variance t-test (two-sided) from summary statistics (mean, sample standard
    deviation with ddof 1, size per side): ``scipy.stats.ttest_ind_from_stats(..., equal_var=False)``.

    The one Welch test of the project: the sample form above and the reproduction scripts' comparisons of our
    trials with a thesis table's mean ± sd (chapters 5 and 7) both come here. The thesis reports its comparisons as
    p-values at alpha = 0.05 (Sec. 7.2, Figs. 7.8, 7.11 and 7.12). Undefined cases give NaN rather than a warning:
    fewer than two values on a side, a NaN statistic, or two constant samples (both standard deviations 0); one
    constant side (an oracle that always takes 11 steps) is a valid Welch case.
    """
    from scipy import stats

    values = (first_mean, first_sd, second_mean, second_sd)
    if first_n < 2 or second_n < 2 or any(math.isnan(v) for v in values) or first_sd == second_sd == 0.0:
        return math.nan, math.nan
    result = stats.ttest_ind_from_stats(
        first_mean, first_sd, first_n, second_mean, second_sd, second_n, equal_var=False
    )
    return float(result.statistic), float(result.pvalue)


@dataclass(frozen=True)
class PairComparison:
    """Two samples of one metric compared: Welch's unequal-variance t-test (two-sided) and the probability that
    ``first`` improves on ``second`` (rliable), with its percentile-bootstrap interval."""

    first: str
    second: str
    metric: str
    statistic: float
    p_value: float
    improvement: float = math.nan
    improvement_low: float = math.nan
    improvement_high: float = math.nan

    def significant(self, alpha: float = 0.05) -> bool:
        return bool(self.p_value < alpha)


def compare_samples(
    first: Sequence[float],
    second: Sequence[float],
    names: tuple[str, str],
    metric: str,
    lower_is_better: bool = True,
) -> PairComparison:
    """Welch test and probability of improvement of ``first`` over ``second`` (``lower_is_better``: steps)."""
    statistic, p_value = welch_test(first, second)
    low, high = improvement_interval(first, second, lower_is_better)
    return PairComparison(
        names[0],
        names[1],
        metric,
        statistic,
        p_value,
        probability_of_improvement(first, second, lower_is_better),
        low,
        high,
    )


def compare_pairs(
    samples: dict[str, Sequence[float]], metric: str, lower_is_better: bool = True
) -> list[PairComparison]:
    """:func:`compare_samples` between every pair of agents, in the order the agents are given."""
    names = list(samples)
    return [
        compare_samples(samples[first], samples[second], (first, second), metric, lower_is_better)
        for i, first in enumerate(names)
        for second in names[i + 1 :]
    ]


# ----------------------------------------------------------------------------------------------- thesis metrics


def normalised_entropies(distributions: np.ndarray) -> np.ndarray:
    """Metric 3 per row of a stack of task posteriors: the normalised entropy ``H̄`` of Sec. 7.1 (one place:
    :func:`embodied_adhoc.decision.agents.task_beliefs.normalised_entropy`), in [0, 1]."""
    from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

    return np.array([normalised_entropy(row) for row in np.atleast_2d(distributions)])


def identify_step(posteriors: np.ndarray, true_task: int, margin: float = IDENTIFY_MARGIN) -> int | None:
    """Thesis Metric 2: the first step ``T`` from which ``true_task``'s posterior exceeds every other task's by more
    than ``margin`` (:data:`IDENTIFY_MARGIN`) at every step to the end.

    ``posteriors[t]`` is the task posterior after ``t`` steps (row 0 = the prior before acting). A tie, or a lead
    within the margin (a rounding artefact), does not count as identified (a uniform prior identifies nothing).
    Returns None if the true task does not lead by the margin at the last step (never identified), or if there
    are no posteriors.
    """
    posteriors = np.asarray(posteriors, dtype=np.float64)
    if posteriors.ndim != 2 or posteriors.shape[0] == 0:
        return None
    true_probability = posteriors[:, true_task]
    others = np.delete(posteriors, true_task, axis=1)
    best_other = others.max(axis=1) if others.shape[1] else np.full(len(posteriors), -np.inf)
    leading = true_probability > best_other + margin
    if not leading[-1]:
        return None
    not_leading = np.flatnonzero(~leading)
    return int(not_leading[-1] + 1) if not_leading.size else 0


def mean_curve(
    curves: Sequence[Sequence[float]],
    confidence: float = CONFIDENCE,
    reps: int = BOOTSTRAP_REPS,
    seed: int = BOOTSTRAP_SEED,
) -> dict[str, np.ndarray]:
    """Per-time-step mean over curves of different lengths, with a percentile-bootstrap band (Fig. 7.9's entropy).

    A finished trial keeps its last value for later steps (its belief no longer changes), so every step averages
    over all trials. Trials are resampled whole (one resample = the same trials at every step), and each step's
    band lies inside that step's [min, max] (an entropy band inside [0, 1]). Returns arrays ``step``, ``mean``,
    ``low``, ``high``, ``n``; NaN band for a single curve.
    """
    curves = [np.asarray(c, dtype=np.float64) for c in curves if len(c)]
    if not curves:
        empty = np.zeros(0)
        return {"step": empty, "mean": empty, "low": empty, "high": empty, "n": empty}
    length = max(c.size for c in curves)
    padded = np.stack([np.concatenate([c, np.full(length - c.size, c[-1])]) for c in curves])
    n = padded.shape[0]
    mean = padded.mean(axis=0)
    if n > 1:
        rng = np.random.default_rng(seed)
        replicates = np.concatenate(
            [_resample_counts(np.arange(n), n, block, rng) @ padded / n for block in _chunks(reps, n)]
        )
        # Each step's resampled means lie in that step's [min, max]; the clip removes floating-point rounding only.
        replicates = np.clip(replicates, padded.min(axis=0), padded.max(axis=0))
        low, high = _percentile_interval(replicates, confidence)
    else:
        low = high = np.full(length, np.nan)
    return {"step": np.arange(length), "mean": mean, "low": low, "high": high, "n": np.full(length, n)}
