"""Statistics of the trial runner against scipy and hand-computed values."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from embodied_adhoc.experiments.stats import (
    compare_pairs,
    holm_adjusted,
    identify_step,
    improvement_interval,
    interquartile_mean,
    mean_curve,
    normalised_entropies,
    probability_of_improvement,
    summarise_sample,
    welch_test,
    welch_test_from_stats,
)


def test_mean_and_sd_by_hand():
    summary = summarise_sample([1, 2, 3, 4, 5])
    assert summary.n == 5 and summary.mean == 3.0
    assert summary.sd == pytest.approx(math.sqrt(2.5))
    assert summary.iqm == pytest.approx(3.0)  # int(0.25 * 5) = 1 trimmed each side: mean of 2, 3, 4


def test_bootstrap_interval_agrees_with_scipy_percentile_bootstrap():
    values = np.random.default_rng(0).normal(12.0, 2.0, size=32)
    summary = summarise_sample(values)
    reference = stats.bootstrap(
        (values,), np.mean, method="percentile", n_resamples=20_000, rng=np.random.default_rng(1)
    ).confidence_interval
    # Two independent Monte-Carlo estimates of the same interval (half width ~0.7 here) agree to within 0.05.
    assert summary.ci_low == pytest.approx(reference.low, abs=0.05)
    assert summary.ci_high == pytest.approx(reference.high, abs=0.05)


def test_interval_of_a_skewed_sample_stays_inside_its_range():
    # 30 trials at the 100-step cap and two quick ones, and the mirror image: the t-interval (mean ± t sd / sqrt n)
    # of the first reaches above 100, that of the second below 0; the bootstrap interval cannot leave [min, max].
    for values in ([100] * 30 + [3, 5], [0] * 30 + [100, 100]):
        summary = summarise_sample(values)
        half = stats.t.ppf(0.975, len(values) - 1) * summary.sd / math.sqrt(len(values))
        assert summary.mean - half < min(values) or summary.mean + half > max(values)  # the old interval lied
        assert min(values) <= summary.ci_low <= summary.mean <= summary.ci_high <= max(values)
        assert min(values) <= summary.iqm_ci_low <= summary.iqm <= summary.iqm_ci_high <= max(values)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.0, 100.0), min_size=2, max_size=40))
def test_interval_inside_the_sample_range_for_any_sample(values):
    summary = summarise_sample(values, reps=300)
    assert min(values) <= summary.ci_low <= summary.ci_high <= max(values)


def test_intervals_are_seeded():
    values = np.random.default_rng(3).exponential(5.0, size=20)
    assert summarise_sample(values) == summarise_sample(values)
    assert summarise_sample(values, seed=1) != summarise_sample(values, seed=2)


def test_iqm_matches_scipy_trim_mean():
    for size in (4, 7, 32, 33):
        values = np.random.default_rng(size).normal(size=size)
        assert interquartile_mean(values) == pytest.approx(stats.trim_mean(values, 0.25))


def test_probability_of_improvement_is_rliables_mann_whitney_u():
    rng = np.random.default_rng(5)
    a, b = rng.integers(8, 20, size=30), rng.integers(9, 25, size=25)  # integers: ties count one half
    u = stats.mannwhitneyu(a, b, alternative="greater").statistic
    assert probability_of_improvement(a, b) == pytest.approx(u / (30 * 25))
    # for steps (lower is better) the roles swap: P(a < b) + P(a = b) / 2 = 1 - P(a > b) - P(a = b) / 2
    assert probability_of_improvement(a, b, lower_is_better=True) == pytest.approx(1 - u / (30 * 25))
    assert probability_of_improvement([1, 2], [1, 2]) == 0.5
    assert probability_of_improvement([1, 1], [5, 6], lower_is_better=True) == 1.0
    low, high = improvement_interval(a, b, lower_is_better=True)
    assert 0.0 <= low <= probability_of_improvement(a, b, lower_is_better=True) <= high <= 1.0


@pytest.mark.parametrize("lower_is_better", [False, True])
def test_improvement_interval_agrees_with_a_brute_force_bootstrap(lower_is_better):
    rng = np.random.default_rng(8)
    a, b = rng.integers(8, 20, size=24), rng.integers(9, 25, size=20)
    replicates = [
        probability_of_improvement(rng.choice(a, a.size), rng.choice(b, b.size), lower_is_better)
        for _ in range(4000)
    ]
    reference = np.quantile(replicates, [0.025, 0.975])
    assert improvement_interval(a, b, lower_is_better) == pytest.approx(tuple(reference), abs=0.03)


def test_degenerate_samples():
    assert math.isnan(summarise_sample([]).mean)
    single = summarise_sample([7])
    assert single.mean == 7 and math.isnan(single.sd) and math.isnan(single.ci_low)
    constant = summarise_sample([11, 11, 11])
    assert constant.ci_low == constant.ci_high == 11


def test_welch_matches_scipy_and_hand_value():
    a = [12, 13, 11, 14, 12, 15]
    b = [20, 25, 18, 30, 22]
    t, p = welch_test(a, b)
    reference = stats.ttest_ind(a, b, equal_var=False)
    assert (t, p) == pytest.approx((reference.statistic, reference.pvalue))
    # by hand: t = (mean_a - mean_b) / sqrt(var_a / n_a + var_b / n_b)
    va, vb = np.var(a, ddof=1), np.var(b, ddof=1)
    assert t == pytest.approx((np.mean(a) - np.mean(b)) / math.sqrt(va / 6 + vb / 5))


def test_welch_undefined_cases_are_nan():
    assert all(math.isnan(v) for v in welch_test([3, 3, 3], [3, 3, 3]))
    assert all(math.isnan(v) for v in welch_test([1], [2, 3]))
    t, p = welch_test([11, 11, 11, 11], [12, 14, 13, 15])  # one constant side is fine
    assert t < 0 and 0 < p < 0.05


def test_welch_from_summary_statistics_matches_scipy():
    # Table 5.5's gridworld ATPO row against the thesis's (mean, sd, n per side)
    ours, thesis = (86.66, 7.09, 32), (86.53, 9.12, 32)
    reference = stats.ttest_ind_from_stats(*ours, *thesis, equal_var=False)
    assert welch_test_from_stats(*ours, *thesis) == pytest.approx((reference.statistic, reference.pvalue))
    # unequal sizes and spreads: the same (t, p) as scipy's test on the samples themselves
    a, b = [12, 13, 11, 14, 12, 15], [20, 25, 18, 30, 22]
    from_samples = stats.ttest_ind(a, b, equal_var=False)
    summary = (np.mean(a), np.std(a, ddof=1), 6, np.mean(b), np.std(b, ddof=1), 5)
    assert welch_test_from_stats(*summary) == pytest.approx((from_samples.statistic, from_samples.pvalue))
    t, p = welch_test_from_stats(98.0, 0.0, 32, 97.19, 0.53, 32)  # one constant side (value iteration on ntu)
    assert t > 0 and p < 1e-6


def test_welch_from_summary_statistics_undefined_cases_are_nan():
    assert all(math.isnan(v) for v in welch_test_from_stats(98.0, 0.0, 32, 98.0, 0.0, 32))  # both constant
    assert all(math.isnan(v) for v in welch_test_from_stats(5.0, 1.0, 1, 6.0, 1.0, 32))  # one value
    assert all(math.isnan(v) for v in welch_test_from_stats(5.0, math.nan, 32, 6.0, 1.0, 32))


def test_compare_pairs_covers_every_pair_in_order():
    tests = compare_pairs({"a": [1, 2, 3], "b": [2, 3, 4], "c": [5, 6, 8]}, "steps")
    assert [(t.first, t.second) for t in tests] == [("a", "b"), ("a", "c"), ("b", "c")]
    assert tests[1].improvement == 1.0  # every trial of a takes fewer steps than every trial of c
    assert tests[1].p_value == pytest.approx(welch_test([1, 2, 3], [5, 6, 8])[1])


def test_normalised_entropy():
    assert normalised_entropies(np.array([0.5, 0.5])) == pytest.approx([1.0])
    assert normalised_entropies(np.array([1.0, 0.0])) == pytest.approx([0.0])
    assert normalised_entropies(np.array([0.25] * 4)) == pytest.approx([1.0])
    stack = normalised_entropies(np.array([[0.5, 0.5], [0.9, 0.1]]))
    expected = -(0.9 * math.log(0.9) + 0.1 * math.log(0.1)) / math.log(2)
    assert stack == pytest.approx([1.0, expected])


@pytest.mark.parametrize(
    ("trace", "true_task", "expected"),
    [
        ([[0.5, 0.5], [0.4, 0.6], [0.2, 0.8]], 1, 1),  # leads from step 1 on
        ([[0.5, 0.5], [0.6, 0.4], [0.4, 0.6], [0.3, 0.7]], 1, 2),  # lost the lead at step 1
        ([[0.5, 0.5], [0.3, 0.7], [0.6, 0.4], [0.2, 0.8]], 1, 3),  # led, lost it, regained it
        ([[0.5, 0.5], [0.3, 0.7], [0.6, 0.4]], 1, None),  # wrong at the end: never identified
        ([[0.5, 0.5], [0.5, 0.5]], 0, None),  # a tie is not identification
        ([[1.0, 0.0], [1.0, 0.0]], 0, 0),  # known from the start
        ([[0.5, 0.5], [0.5000000000000001, 0.5]], 0, None),  # a rounding artefact is not a lead
        ([[0.5, 0.5], [0.5000000000000001, 0.5], [0.6, 0.4]], 0, 2),
        ([[0.5, 0.5], [0.5 + 1e-5, 0.5 - 1e-5]], 0, 1),  # a lead above the 1e-6 margin counts
        ([[0.2, 0.3, 0.5], [0.2, 0.5, 0.3], [0.1, 0.6, 0.3]], 1, 1),
    ],
)
def test_identify_step_metric_2(trace, true_task, expected):
    assert identify_step(np.array(trace), true_task) == expected


def test_mean_curve_holds_last_value_of_finished_trials():
    curve = mean_curve([[1.0, 0.5], [1.0, 0.8, 0.2, 0.0]])
    assert list(curve["step"]) == [0, 1, 2, 3]
    assert curve["mean"] == pytest.approx([1.0, 0.65, 0.35, 0.25])
    assert curve["low"][0] == pytest.approx(1.0) and curve["high"][0] == pytest.approx(1.0)
    assert np.all(curve["low"] <= curve["mean"]) and np.all(curve["mean"] <= curve["high"])


def test_entropy_band_stays_inside_0_1():
    # Skewed entropy curves: most trials resolve the task at once, a few stay undecided. mean ± t sd / sqrt(n)
    # leaves [0, 1] here; the bootstrap band cannot.
    curves = [[1.0, 0.0]] * 14 + [[1.0, 1.0, 1.0]] * 2
    curve = mean_curve(curves)
    padded = np.array([c + [c[-1]] * (3 - len(c)) for c in curves])
    half = stats.t.ppf(0.975, 15) * padded.std(axis=0, ddof=1) / 4.0
    assert np.any(padded.mean(axis=0) - half < 0.0)
    assert np.all(curve["low"] >= 0.0) and np.all(curve["high"] <= 1.0)
    assert np.all(curve["low"] <= curve["mean"]) and np.all(curve["mean"] <= curve["high"])
    assert mean_curve(curves)["low"] == pytest.approx(curve["low"])  # seeded


def test_holm_adjustment_by_hand():
    # sorted 0.01, 0.02, 0.04 scaled by 3, 2, 1 -> 0.03, 0.04, 0.04; the input's order kept
    assert holm_adjusted([0.04, 0.01, 0.02]).tolist() == pytest.approx([0.04, 0.03, 0.04])
    assert holm_adjusted([0.5, 0.9]).tolist() == [1.0, 1.0]  # capped at 1
    assert holm_adjusted([]).size == 0


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30))
def test_holm_never_lowers_a_p_value_and_keeps_their_order(pvalues):
    adjusted = holm_adjusted(pvalues)
    assert np.all(adjusted >= np.asarray(pvalues) - 1e-15) and np.all(adjusted <= 1.0)
    order = np.argsort(pvalues, kind="stable")
    assert np.all(np.diff(adjusted[order]) >= 0)
