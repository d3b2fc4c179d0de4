"""Aggregate benchmark scores with rliable's definitions (Agarwal et al. 2021), in numpy.

A score matrix has shape ``(episodes, members)``: ``scores[n, m]`` is the normalised score of episode ``n`` with
member ``m`` (the members are rliable's tasks, the episodes its runs).

* IQM: the 25 %-trimmed mean over every entry (``experiments.stats.interquartile_mean``, as ``aggregate_iqm``);
* mean: the mean over members of the per-member mean (``aggregate_mean``);
* stratified bootstrap: each resample draws, for every member separately, as many episodes with replacement as it
  has (``StratifiedBootstrap``); intervals are percentiles of the resampled statistic;
* probability of improvement ``P(X > Y)``: per member the Mann-Whitney statistic over the episode pairs (ties
  count one half; ``experiments.stats.probability_of_improvement``), averaged over members; its interval
  resamples X and Y independently within each member (``StratifiedIndependentBootstrap``);
* performance profile (score distribution): the fraction of all entries above each threshold ``tau``.

Every resample comes from a generator seeded by :data:`~embodied_adhoc.experiments.stats.BOOTSTRAP_SEED`, so the
same scores give the same intervals.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.experiments.stats import (
    BOOTSTRAP_SEED,
    CONFIDENCE,
    interquartile_mean,
    probability_of_improvement,
)

__all__ = [
    "BENCH_REPS",
    "aggregate",
    "improvement",
    "mean_of_means",
    "profile",
    "stratified_interval",
]

BENCH_REPS = 2000
"""Bootstrap resamples of every benchmark interval."""

_BLOCK = 250  # resamples per block: memory stays bounded for large suites


def mean_of_means(scores: np.ndarray) -> np.ndarray | float:
    """rliable's aggregate mean: the mean over members (last axis) of the mean over episodes (the one before)."""
    return np.asarray(scores).mean(axis=-2).mean(axis=-1)


def _iqm_of_blocks(block: np.ndarray) -> np.ndarray:
    return interquartile_mean(block.reshape(block.shape[0], -1), axis=1)


def _resample(scores: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` stratified resamples, shape ``(count, episodes, members)``."""
    n, m = scores.shape
    rows = rng.integers(0, n, size=(count, n, m))
    return scores[rows, np.arange(m)[None, None, :]]


def _blocks(reps: int) -> list[int]:
    return [min(_BLOCK, reps - start) for start in range(0, reps, _BLOCK)]


def stratified_interval(
    scores: np.ndarray,
    statistic,
    reps: int = BENCH_REPS,
    seed: int = BOOTSTRAP_SEED,
    confidence: float = CONFIDENCE,
) -> np.ndarray:
    """Percentile interval ``[[low...], [high...]]`` of ``statistic`` (mapping ``(count, episodes, members)`` to
    ``(count, ...)``) under the stratified bootstrap; NaN for fewer than two episodes."""
    scores = np.asarray(scores, dtype=np.float64)
    probe = np.asarray(statistic(scores[None]))[0]
    if scores.shape[0] < 2:
        return np.full((2, *probe.shape), np.nan)
    rng = np.random.default_rng(seed)
    replicates = np.concatenate([np.asarray(statistic(_resample(scores, c, rng))) for c in _blocks(reps)])
    tail = (1.0 - confidence) / 2.0
    return np.quantile(replicates, [tail, 1.0 - tail], axis=0)


def aggregate(scores: np.ndarray, reps: int = BENCH_REPS, seed: int = BOOTSTRAP_SEED) -> dict:
    """IQM and mean of a score matrix with their stratified-bootstrap intervals."""
    scores = np.asarray(scores, dtype=np.float64)
    iqm_ci = stratified_interval(scores, _iqm_of_blocks, reps, seed)
    mean_ci = stratified_interval(scores, mean_of_means, reps, seed)
    return {
        "iqm": float(interquartile_mean(scores.ravel())),
        "iqm_ci": [float(v) for v in iqm_ci],
        "mean": float(mean_of_means(scores)),
        "mean_ci": [float(v) for v in mean_ci],
    }


def _improvement_blocks(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``P(X > Y)`` of resampled blocks ``(count, n, m)`` and ``(count, k, m)``: one value per resample."""
    difference = x[:, :, None, :] - y[:, None, :, :]
    per_member = ((difference > 0) + 0.5 * (difference == 0)).mean(axis=(1, 2))
    return per_member.mean(axis=1)


def improvement(x: np.ndarray, y: np.ndarray, reps: int = BENCH_REPS, seed: int = BOOTSTRAP_SEED) -> dict:
    """rliable's average probability of improvement of X over Y with its interval (see the module docstring)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    point = float(np.mean([probability_of_improvement(x[:, m], y[:, m]) for m in range(x.shape[1])]))
    if min(x.shape[0], y.shape[0]) < 2:
        return {"p": point, "ci": [float("nan")] * 2}
    rng = np.random.default_rng(seed)
    replicates = np.concatenate(
        [_improvement_blocks(_resample(x, c, rng), _resample(y, c, rng)) for c in _blocks(reps)]
    )
    tail = (1.0 - CONFIDENCE) / 2.0
    low, high = np.quantile(replicates, [tail, 1.0 - tail])
    return {"p": point, "ci": [float(low), float(high)]}


def profile(scores: np.ndarray, taus: np.ndarray, reps: int = BENCH_REPS, seed: int = BOOTSTRAP_SEED) -> dict:
    """The score distribution ``P(score > tau)`` at each ``tau`` with its stratified-bootstrap band."""
    scores = np.asarray(scores, dtype=np.float64)
    taus = np.asarray(taus, dtype=np.float64)

    def fraction(block: np.ndarray) -> np.ndarray:
        flat = block.reshape(block.shape[0], -1)
        return (flat[:, :, None] > taus[None, None, :]).mean(axis=1)

    band = stratified_interval(scores, fraction, reps, seed)
    return {
        "tau": [float(t) for t in taus],
        "fraction": [float(v) for v in fraction(scores[None])[0]],
        "low": [float(v) for v in band[0]],
        "high": [float(v) for v in band[1]],
    }
