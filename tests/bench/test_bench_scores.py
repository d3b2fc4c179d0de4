"""The benchmark's aggregate scores against rliable's definitions, computed here another way."""

import numpy as np
import pytest
from scipy import stats as scipy_stats

from embodied_adhoc.bench.scores import aggregate, improvement, mean_of_means, profile, stratified_interval


def _scores(seed: int, shift: float = 0.0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.5 + shift, 0.3, size=(12, 5))


def test_point_estimates_follow_rliable():
    scores = _scores(0)
    summary = aggregate(scores, reps=200)
    assert summary["iqm"] == pytest.approx(scipy_stats.trim_mean(scores, 0.25, axis=None))
    assert summary["mean"] == pytest.approx(np.mean(np.mean(scores, axis=0)))
    assert summary["iqm_ci"][0] <= summary["iqm"] <= summary["iqm_ci"][1]
    assert summary["mean_ci"][0] <= summary["mean"] <= summary["mean_ci"][1]
    assert aggregate(scores, reps=200) == summary  # seeded: same scores, same intervals


def test_stratified_bootstrap_resamples_within_each_member():
    # each member's column is constant, so any within-member resample leaves every column, and the mean, unchanged
    columns = np.tile(np.arange(5.0), (8, 1))
    low, high = stratified_interval(columns, mean_of_means, reps=100)
    assert low == pytest.approx(2.0) and high == pytest.approx(2.0)


def test_probability_of_improvement_is_the_mann_whitney_statistic_averaged_over_members():
    x, y = _scores(1, shift=0.2), _scores(2)
    expected = np.mean(
        [
            scipy_stats.mannwhitneyu(x[:, m], y[:, m], alternative="greater").statistic
            / (x.shape[0] * y.shape[0])
            for m in range(x.shape[1])
        ]
    )
    result = improvement(x, y, reps=200)
    assert result["p"] == pytest.approx(expected)
    assert result["ci"][0] <= result["p"] <= result["ci"][1]
    assert improvement(x, x, reps=50)["p"] == pytest.approx(0.5)
    assert improvement(x, y, reps=200)["p"] + improvement(y, x, reps=200)["p"] == pytest.approx(1.0)


def test_profile_is_the_fraction_above_each_threshold():
    scores = _scores(3)
    taus = np.array([-1.0, 0.0, 0.5, 1.0, 5.0])
    curve = profile(scores, taus, reps=100)
    assert curve["fraction"] == pytest.approx([np.mean(scores > t) for t in taus])
    assert curve["fraction"][0] == 1.0 and curve["fraction"][-1] == 0.0
    assert all(
        lo <= f <= hi for lo, f, hi in zip(curve["low"], curve["fraction"], curve["high"], strict=True)
    )
